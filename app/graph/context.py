"""The true facts of the current decision, derived from the problem and the graph state."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from app.domain.decision import DecisionContext
from app.domain.modes import strategic_weights
from app.domain.phases import Phase
from app.domain.problem import Problem

# robot -> feature -> (basis, reports): app.domain.estimates.rate_notes
RateNotes = Mapping[str, Mapping[str, tuple[str, int]]]


def _rate_note(notes: Mapping[str, tuple[str, int]], features: tuple[str, ...]) -> str:
    parts = []
    for feature in features:
        if feature in notes:
            basis, reports = notes[feature]
            parts.append(
                f"{feature} configured, no reports yet"
                if basis == "prior"
                else f"{feature} {basis} on {reports} reports"
            )
    return "; ".join(parts)


def decision_context(
    problem: Problem,
    state: Mapping[str, Any],
    *,
    tier: int = 0,
    rate_notes: RateNotes | None = None,
) -> DecisionContext:
    inst, cap = problem.instance, problem.cap
    t = state["task_index"]
    loads = tuple(state["loads"])
    task = inst.tasks[t]
    view = state["view"]
    phase = Phase(view["phase"])
    bounds = None if cap.max_deviation is None else (cap.lower, cap.upper)
    return DecisionContext(
        task_index=t,
        total_tasks=inst.n_tasks,
        task_name=task.name,
        features=task.features,
        robot_names=tuple(r.name for r in inst.robots),
        robot_labels=tuple(r.display for r in inst.robots),
        success=tuple(float(x) for x in inst.success[t]),
        loads=loads,
        target=problem.target,
        feasible=tuple(view["feasible"]),
        phase=phase,
        mode=problem.mode,
        weights=strategic_weights(problem.mode, phase),
        tier=tier,
        guided_robot=view["guided_robot"],
        guided_costs=tuple(costs) if (costs := view.get("guided_costs")) is not None else None,
        task_type=task.type,
        load_bounds=bounds,
        attempt=state.get("attempt") or 1,
        rate_notes=tuple(_rate_note(rate_notes.get(r.name, {}), task.features) for r in inst.robots)
        if rate_notes
        else (),
    )
