"""The pinned decisions of a revision (docs/living-plans.md#pins) as its own decision rows: the
parent's robot, success and reasoning, with loads and balance counted in the revision's terms."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from app.domain.metrics import balance_score, severity
from app.domain.problem import Problem
from app.graph.recorder import DecisionRecord


@dataclass(frozen=True)
class ParentDecision:
    record: DecisionRecord
    chain_hash: str | None


def pinned_rows(
    problem: Problem,
    origin: Sequence[int | None],
    decided: Mapping[int, ParentDecision],
    facts: Mapping[int, tuple[float, float]] | None = None,
) -> list[dict[str, Any]]:
    """The revision's own decision rows for its pins, in task order: the parent's robot,
    success and reasoning; loads and balance counted in the revision's terms (pins on
    available robots, W of the available fleet); regret 0 (nothing was chosen here)."""
    inst, cap = problem.instance, problem.cap
    loads = [0] * inst.n_robots
    rows: list[dict[str, Any]] = []
    for index in sorted(problem.pinned):
        source_index = origin[index]
        assert source_index is not None
        parent = decided[source_index]
        d = parent.record
        robot = problem.pinned[index]
        before = list(loads)
        # A pinned team adds one to each available member
        # (docs/living-plans.md#teams-in-a-revision).
        for member in problem.pinned_teams.get(index, (robot,)):
            if member not in problem.unavailable:
                loads[member] += 1
        task = inst.tasks[index]
        rows.append(
            {
                "task_index": index,
                "task_id": str(task.id),
                "task_name": task.name,
                "robot": robot,
                "robot_name": inst.robots[robot].name,
                "phase": d.phase,
                "expected_success": d.expected_success,
                "reasoning": d.reasoning,
                "confidence": d.confidence,
                "tradeoff": d.tradeoff,
                "quality": d.quality,
                "fallback": d.fallback,
                "attempts": 0,
                "failure_log": [],
                "loads_before": before,
                "loads_after": list(loads),
                "balance_before": balance_score(cap.balanced(before), problem.target),
                "balance_after": balance_score(cap.balanced(loads), problem.target),
                "severity_after": severity(cap.balanced(loads), problem.target).value,
                "regret": 0.0,
                # A supervisor's approval or override of the pinned decision stays with it.
                "review": d.review,
                "pinned": True,
                "pinned_from": parent.chain_hash,
                **({"team": d.team} if d.team else {}),
                **_times(problem, index, (facts or {}).get(index)),
            }
        )
    return rows


def _times(problem: Problem, index: int, fact: tuple[float, float] | None) -> dict[str, Any]:
    """docs/living-plans.md#a-revision-in-time: a pin the site reported keeps its reported times
    (and its zone). A pin without a report gets its time when the revision's graph places it, so its
    row has none (app.runs.views.run_schedule places it the same way)."""
    if fact is None:
        return {}
    return {"start": fact[0], "end": fact[1], "zone": problem.instance.tasks[index].zone}
