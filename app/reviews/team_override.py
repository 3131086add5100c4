"""An override of a team decision (docs/reviews.md#reviews-of-team-decisions), checked before it
is stored: the reviewer sends the whole team, which must be a team of the task (every unit
covered, one distinct robot per unit that may cover its feature) and keep the workload cap
satisfiable from the loads the decision was proposed at.

The team is checked against the run's own problem (its spec, as the worker plans it): for a
team the review listed, its `cap_feasible` is what the graph found; for any other team, the
graph's own question (`app.graph.context.team_facts`, the one validation, the candidates and
the fallback ask): the cap for the tasks still to decide and, on a timed run, "members free in
time" from the decisions made so far replayed, unless no team the cap allows is free in time,
when time rules out no one (docs/schedules.md#teams-in-a-run-in-time).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from app.domain.errors import DomainError
from app.domain.pins import pinned_team
from app.domain.problem import Problem
from app.domain.scheduling.progress import TimedProgress
from app.graph.context import team_facts
from app.graph.recorder import DecisionRecord
from app.graph.timing import decision_teams


def checked_team(
    problem: Problem,
    payload: Mapping[str, Any],
    task_index: int,
    robot: str | None,
    team: Sequence[tuple[str, str]] | None,
    made: Sequence[DecisionRecord] = (),
) -> list[tuple[str, str]]:
    """The override's team as (robot, feature) per unit, in unit order; DomainError (422)
    naming the field otherwise. `problem`: the one the run decides (a guided timed run's in its
    plan's order), `made`: its stored decisions."""
    needs = ", ".join(f"{u['count']} x '{u['feature']}'" for u in payload.get("units") or ())
    if team is None:
        raise DomainError(
            "robot",
            f"task index {task_index} ({payload['task_name']}) is a team task ({needs}): to "
            'override it, send `team`, [{"robot", "feature"}] one per unit, not one robot',
            code="team_required",
        )
    instance = problem.instance
    members = pinned_team(instance, task_index, team, "team")
    names = [r.name for r in instance.robots]
    if robot is not None and instance.robot_index(robot) != members[0]:
        raise DomainError(
            "robot",
            f"robot '{robot}' is not the member covering the first unit of the team sent "
            f"('{names[members[0]]}'); give that robot or leave `robot` out",
            code="team_required",
        )
    units = instance.units[task_index]
    chosen = [(names[m], f) for f, m in zip(units, members, strict=True)]
    listed = {
        frozenset((m["robot"], m["feature"]) for m in alt["team"]): alt
        for alt in payload["alternatives"]
        if alt.get("team")
    }
    alt = listed.get(frozenset(chosen))
    if alt is not None:
        why = None if alt["cap_feasible"] else "the workload cap could no longer be met"
    else:
        loads = tuple(int(payload["loads"][name]) for name in names)
        why = _graph_check(problem, task_index, loads, members, made)
    if why is not None:
        raise DomainError(
            "team",
            f"the team {' + '.join(n for n, _ in chosen)} cannot take task index {task_index}: "
            f"{why}",
            code="cap_infeasible",
        )
    return chosen


def _graph_check(
    problem: Problem,
    task: int,
    loads: tuple[int, ...],
    members: tuple[int, ...],
    made: Sequence[DecisionRecord],
) -> str | None:
    """The graph's own question of a team (app.graph.context.team_facts): the cap for the tasks
    still to decide and, on a timed run, members free in time (unless no team the cap allows
    is), asked from the time lines of the decisions made so far."""
    progress = _progress(problem, task, made)
    later = None if progress is None else progress.later(task)
    feasible = tuple(
        problem.feasible_robots(task, loads, 0, in_order=True if later is None else later)
    )
    facts, _ = team_facts(
        problem,
        task,
        loads,
        feasible,
        None,
        timing=() if progress is None else progress.options(task),
        team_time=None if progress is None else (lambda m: progress.team_option(task, m)),
        later=later,
    )
    return None if facts is None else facts.problem(members)


def _progress(problem: Problem, task: int, made: Sequence[DecisionRecord]) -> TimedProgress | None:
    """A timed run's time lines at `task`, the stored decisions placed; None untimed."""
    if not problem.instance.timed:
        return None
    robots = {d.task_index: d.robot for d in made}
    teams = decision_teams(problem, made)
    progress = TimedProgress.replay(problem, robots, until=task, teams=teams)
    return progress if progress.current() == task else None
