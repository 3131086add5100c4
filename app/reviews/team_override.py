"""An override of a team decision (docs/reviews.md#reviews-of-team-decisions), checked before it
is stored: the reviewer sends the whole team, which must be a team of the task (every unit
covered, one distinct robot per unit that may cover its feature) and keep the workload cap
satisfiable from the loads the decision was proposed at.

The team is checked against the run's own problem (its spec, as the worker plans it): for a
team the review listed, its `cap_feasible` is what the graph found; for any other team, the
problem's cap check (`Problem.team_problem`), the one the graph's validation asks, and on a
timed run "members free in time" (the decisions made so far replayed, as the graph's time
lines hold them): unless no listed team the cap allows is free in time either, when time rules
out no one, as in the graph (docs/schedules.md#teams-in-a-run-in-time).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from app.domain.errors import DomainError
from app.domain.pins import pinned_team
from app.domain.problem import Problem
from app.domain.scheduling.progress import TimedProgress
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
        loads = [int(payload["loads"][name]) for name in names]
        progress = _progress(problem, task_index, made)
        later = None if progress is None else progress.later(task_index)
        why = problem.team_problem(task_index, loads, members, later)
        if why is None and progress is not None:
            why = _not_in_time(progress, task_index, members, payload, names)
    if why is not None:
        raise DomainError(
            "team",
            f"the team {' + '.join(n for n, _ in chosen)} cannot take task index {task_index}: "
            f"{why}",
            code="cap_infeasible",
        )
    return chosen


def _progress(problem: Problem, task: int, made: Sequence[DecisionRecord]) -> TimedProgress | None:
    """A timed run's time lines at `task`, the stored decisions placed; None untimed."""
    if not problem.instance.timed:
        return None
    robots = {d.task_index: d.robot for d in made}
    teams = decision_teams(problem, made)
    progress = TimedProgress.replay(problem, robots, until=task, teams=teams)
    return progress if progress.current() == task else None


def _not_in_time(
    progress: TimedProgress,
    task: int,
    members: tuple[int, ...],
    payload: Mapping[str, Any],
    names: Sequence[str],
) -> str | None:
    """Why the team is not free in time (its end misses the deadline or a member's shift), when
    some listed team the cap allows is (else time rules out no one, as in the graph)."""
    option = progress.team_option(task, members)
    if option.allowed:
        return None
    index = {name: i for i, name in enumerate(names)}
    rivals = (
        tuple(index[m["robot"]] for m in alt["team"])
        for alt in payload["alternatives"]
        if alt.get("team") and alt["cap_feasible"]
    )
    if not any(progress.team_option(task, m).allowed for m in rivals):
        return None
    return (
        f"the team would start at minute {option.start:g} and end at {option.end:g}, which "
        f"{option.why_not}"
    )
