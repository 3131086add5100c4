"""What a scheduling call answers (`ScheduleOutcome`) and what its paths start from."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from app.domain.objective import ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.schedule import Schedule
from app.solvers.cpsat.common import Candidates, Search, SuccessWeights
from app.solvers.cpsat.time_scale import TimeScale


@dataclass
class ScheduleOutcome:
    schedule: Schedule
    status: str  # "optimal" only when proven; else "feasible"
    model: str
    objective: ObjectiveKind
    makespan: float
    bound: float  # a proven lower bound on the makespan at the ES reached
    gap: float  # (makespan - bound) / makespan
    expected_success: float
    expected_success_bound: float  # the time-free optimum: no schedule does better
    wall_s: float
    stages: list[dict[str, Any]] = field(default_factory=list)
    bound_source: str = ""  # which relaxation (or the search) gives `bound`
    bounds: dict[str, float] = field(default_factory=dict)  # every floor computed, minutes
    budget: dict[str, Any] = field(default_factory=dict)
    trajectory: list[tuple[float, float, float, float, float]] = field(default_factory=list)

    def details(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "objective": self.objective.value,
            "objective_value": self.makespan,
            "bound": self.bound,
            "gap": self.gap,
            "model": self.model,
            "expected_success": self.expected_success,
            "expected_success_bound": self.expected_success_bound,
            "wall_s": self.wall_s,
            "stages": self.stages,
            "bound_source": self.bound_source,
            "bounds": {k: round(v, 6) for k, v in self.bounds.items()},
            "budget": self.budget,
            "trajectory": [list(p) for p in self.trajectory],
            "schedule": self.schedule,
        }


@dataclass
class Setup:
    """What both paths start from: the budget, the weights, the time-free optimum, the
    feasible schedules so far and the ES condition of the objective."""

    problem: Problem
    search: Search
    scale: TimeScale
    weights: SuccessWeights
    feasible: Candidates
    es_bound: int  # the time-free optimum's ES, in weight units
    es_target: int | None  # success_then_makespan: the ES to hold, once known
    es_floor: int | None  # makespan: the least ES allowed
    pairs: set[tuple[int, int]] | None  # the only pairs stage 2 may use, when known


def outcome(
    setup: Setup, best: Schedule, status: str, model: str, bound: float, source: str = ""
) -> ScheduleOutcome:
    search = setup.search
    search.mark(best.makespan, bound)
    gap = 0.0 if best.makespan <= 0 else max(0.0, (best.makespan - bound) / best.makespan)
    return ScheduleOutcome(
        schedule=best,
        status=status,
        model=model,
        objective=setup.problem.objective.kind,
        makespan=best.makespan,
        bound=bound,
        gap=gap,
        expected_success=setup.weights.mean(setup.weights.of(best.assignment)),
        expected_success_bound=setup.weights.mean(setup.es_bound),
        wall_s=search.elapsed(),
        stages=search.stages,
        bound_source=source,
        budget=search.summary(),
        trajectory=search.trajectory,
    )
