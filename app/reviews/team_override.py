"""An override of a team decision (docs/reviews.md#reviews-of-team-decisions), checked before it
is stored: the reviewer sends the whole team, which must be a team of the task (every unit
covered, one distinct robot per unit that may cover its feature) and keep the workload cap
satisfiable from the loads the decision was proposed at.

The team is checked against the run's own problem (its spec, as the worker plans it): for a
team the review listed, its `cap_feasible` is what the graph found; for any other team, the
problem's cap check (`Problem.team_problem`), the one the graph's validation asks.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from app.domain.errors import DomainError
from app.domain.pins import pinned_team
from app.runs.spec import RunSpec


def checked_team(
    request: dict[str, Any],
    payload: Mapping[str, Any],
    task_index: int,
    robot: str | None,
    team: Sequence[tuple[str, str]] | None,
) -> list[tuple[str, str]]:
    """The override's team as (robot, feature) per unit, in unit order; DomainError (422)
    naming the field otherwise."""
    needs = ", ".join(f"{u['count']} x '{u['feature']}'" for u in payload.get("units") or ())
    if team is None:
        raise DomainError(
            "robot",
            f"task index {task_index} ({payload['task_name']}) is a team task ({needs}): to "
            'override it, send `team`, [{"robot", "feature"}] one per unit, not one robot',
            code="team_required",
        )
    problem = RunSpec.from_json(request).problem
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
        why = problem.team_problem(task_index, loads, members)
    if why is not None:
        raise DomainError(
            "team",
            f"the team {' + '.join(n for n, _ in chosen)} cannot take task index {task_index}: "
            f"{why}",
            code="cap_infeasible",
        )
    return chosen
