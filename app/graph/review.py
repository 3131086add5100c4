"""The review gate at the end of finalize: evaluate the run's review policy on the true facts
of the proposed decision and, when a trigger fires, pause the graph with `interrupt()`
before the decision touches the loads or the record
(docs/reviews.md#which-decisions-wait-for-review).

Everything before `interrupt()` is a pure computation over the recorder's rows (no LLM
call), because LangGraph re-runs the node from its top when the graph is resumed. A replay
re-applies the original run's resolutions and never waits.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from langgraph.types import interrupt

from app.domain.decision import DecisionContext, Members
from app.domain.models import TaskId
from app.domain.review import Proposal, Resolution, ReviewAction, ReviewPolicy
from app.graph.review_teams import members_of, team_alternatives, team_json, team_units

# (task index, loads before, robot) -> success points given away over the rest of the queue
# against the exact optimum (the unit of the guidance costs), or None if the cap forbids it.
# On a team task the third argument is the team's members (a tuple), which the unit oracle
# reads (app.solvers.unit_oracle.UnitOracle.loss); Any keeps one callable for both.
Cost = Callable[[int, Sequence[int], Any], float | None]


@dataclass(frozen=True)
class ReviewGate:
    policy: ReviewPolicy | None
    cost: Cost
    # A replay: the original run's resolutions by task index, re-applied without waiting.
    recorded: Mapping[int, Resolution] | None = None


@dataclass(frozen=True)
class Reviewed:
    robot: int
    review: dict[str, Any]
    team: Members | None = None  # a team decision: the members after the review


def review_payload(
    dctx: DecisionContext,
    *,
    task_id: TaskId,
    robot: int,
    decision: Mapping[str, Any],
    reasoning: str,
    tradeoff: str,
    triggers: Sequence[str],
    costs: Sequence[float | None],
    team: Members | None = None,
    cost: Cost | None = None,
) -> dict[str, Any]:
    """What a supervisor sees (GET /reviews); checkpointed with the interrupt, so plain JSON.
    A team decision's proposal carries its team, and its alternatives are teams
    (docs/reviews.md#reviews-of-team-decisions)."""
    names = dctx.robot_names
    if team is not None and dctx.team is not None and cost is not None:
        facts = dctx.team
        return {
            "task_index": dctx.task_index,
            "task_id": task_id,
            "task_name": dctx.task_name,
            "proposal": {
                "robot": names[team[0]],
                "team": team_json(facts.units, names, team),
                "success": facts.success(team),
                "reasoning": reasoning,
                "tradeoff": tradeoff,
                "quality": decision["quality"],
                "confidence": decision["confidence"],
                "fallback": decision["fallback"],
            },
            "triggers": list(triggers),
            "alternatives": team_alternatives(
                dctx, team, lambda m: cost(dctx.task_index, dctx.loads, m)
            ),
            "units": team_units(facts, names),
            "loads": dict(zip(names, dctx.loads, strict=True)),
        }
    return {
        "task_index": dctx.task_index,
        "task_id": task_id,
        "task_name": dctx.task_name,
        "proposal": {
            "robot": names[robot],
            "success": dctx.success[robot],
            "reasoning": reasoning,
            "tradeoff": tradeoff,
            "quality": decision["quality"],
            "confidence": decision["confidence"],
            "fallback": decision["fallback"],
        },
        "triggers": list(triggers),
        "alternatives": [
            {
                "robot": names[r],
                "success": dctx.success[r],
                "load": dctx.loads[r],
                "cap_feasible": r in dctx.feasible,
                "regret_if_chosen": costs[r],
            }
            for r in range(len(names))
        ],
    }


def apply(
    resolution: Resolution,
    proposed: int,
    names: Sequence[str],
    team: Members | None = None,
    units: Sequence[str] = (),
) -> Reviewed:
    review: dict[str, Any] = {
        "action": resolution.action.value,
        "reviewer": resolution.reviewer,
        "reason": resolution.reason,
        "at": resolution.at,
        "triggers": list(resolution.triggers),
    }
    robot = proposed
    if resolution.action is not ReviewAction.OVERRIDE:
        return Reviewed(robot=robot, review=review, team=team)
    if team is not None and resolution.team is not None:
        # The reviewer's team, in unit order (the service checked it as a team); the
        # decision keeps the proposed one beside it, its first member as for one robot.
        chosen = members_of(resolution.team, names)
        review["overridden_from"] = names[proposed]
        review["overridden_from_team"] = team_json(units, names, team)
        return Reviewed(robot=chosen[0], review=review, team=chosen)
    if resolution.robot is not None:
        robot = list(names).index(resolution.robot)
        review["overridden_from"] = names[proposed]
    return Reviewed(robot=robot, review=review, team=team)


def gate(
    g: ReviewGate,
    dctx: DecisionContext,
    *,
    task_id: TaskId,
    robot: int,
    decision: Mapping[str, Any],
    text: Callable[[], tuple[str, str]],
    team: Members | None = None,
) -> Reviewed | None:
    """None: the decision goes ahead as proposed. Otherwise the reviewed robot (and team, on
    a team task) and the review record; the first call for a decision that needs review does
    not return (the graph pauses) until the run is resumed with the resolution."""
    t, names = dctx.task_index, dctx.robot_names
    units = dctx.team.units if dctx.team is not None else ()
    if g.recorded is not None:
        recorded = g.recorded.get(t)
        return None if recorded is None else apply(recorded, robot, names, team, units)
    if g.policy is None:
        return None
    if team is None:
        costs = [_rounded(g.cost(t, dctx.loads, r)) for r in range(len(names))]
        regret = costs[robot]
    else:
        costs, regret = [], _rounded(g.cost(t, dctx.loads, tuple(team)))
    proposal = Proposal(
        task_id=str(task_id),  # the policy names tasks as strings, whatever the request's type
        features=dctx.features,
        robot=names[robot],
        fallback=bool(decision["fallback"]),
        confidence=str(decision["confidence"]),
        quality=float(decision["quality"]),
        regret_points=regret,
        members=tuple(names[m] for m in team or ()),
    )
    triggers = [x.value for x in g.policy.triggers(proposal)]
    if not triggers:
        return None
    reasoning, tradeoff = text()
    answer = interrupt(
        review_payload(
            dctx,
            task_id=task_id,
            robot=robot,
            decision=decision,
            reasoning=reasoning,
            tradeoff=tradeoff,
            triggers=triggers,
            costs=costs,
            team=team,
            cost=g.cost,
        )
    )
    return apply(Resolution.from_json(answer), robot, names, team, units)


def _rounded(cost: float | None) -> float | None:
    return None if cost is None else round(max(0.0, cost), 6)
