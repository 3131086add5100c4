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

from app.domain.decision import DecisionContext
from app.domain.models import TaskId
from app.domain.review import Proposal, Resolution, ReviewAction, ReviewPolicy

# (task index, loads before, robot) -> success points given away over the rest of the queue
# against the exact optimum (the unit of the guidance costs), or None if the cap forbids it.
Cost = Callable[[int, Sequence[int], int], float | None]


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
) -> dict[str, Any]:
    """What a supervisor sees (GET /reviews); checkpointed with the interrupt, so plain JSON."""
    names = dctx.robot_names
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


def apply(resolution: Resolution, proposed: int, names: Sequence[str]) -> Reviewed:
    review: dict[str, Any] = {
        "action": resolution.action.value,
        "reviewer": resolution.reviewer,
        "reason": resolution.reason,
        "at": resolution.at,
        "triggers": list(resolution.triggers),
    }
    robot = proposed
    if resolution.action is ReviewAction.OVERRIDE and resolution.robot is not None:
        robot = list(names).index(resolution.robot)
        review["overridden_from"] = names[proposed]
    return Reviewed(robot=robot, review=review)


def gate(
    g: ReviewGate,
    dctx: DecisionContext,
    *,
    task_id: TaskId,
    robot: int,
    decision: Mapping[str, Any],
    text: Callable[[], tuple[str, str]],
) -> Reviewed | None:
    """None: the decision goes ahead as proposed. Otherwise the reviewed robot and the
    review record; the first call for a decision that needs review does not return (the
    graph pauses) until the run is resumed with the resolution."""
    t, names = dctx.task_index, dctx.robot_names
    if g.recorded is not None:
        recorded = g.recorded.get(t)
        return None if recorded is None else apply(recorded, robot, names)
    if g.policy is None:
        return None
    costs = [
        None if (c := g.cost(t, dctx.loads, r)) is None else round(max(0.0, c), 6)
        for r in range(len(names))
    ]
    proposal = Proposal(
        task_id=str(task_id),  # the policy names tasks as strings, whatever the request's type
        features=dctx.features,
        robot=names[robot],
        fallback=bool(decision["fallback"]),
        confidence=str(decision["confidence"]),
        quality=float(decision["quality"]),
        regret_points=costs[robot],
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
        )
    )
    return apply(Resolution.from_json(answer), robot, names)
