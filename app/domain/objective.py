"""What "optimal" means for a timed plan (docs/schedules.md#the-model).

The objective lives on the Problem, beside the mode and the workload cap, not on the
Instance. The instance is the site as it is (tasks, robots, durations, zones, shifts);
the problem is the question asked of it (how to trade success against balance, which cap,
which pins, and now what to optimise in time). The benchmark measures every method on
both objectives over one instance, a revision may change the objective without changing
the site, and the exact allocation solvers never read it: keeping it off the instance
keeps the instance's equality, hash and stored form about facts only. The request still
sends `objective` and `min_expected_success` with the instance fields; the API layer
passes them to `Problem.build`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

from app.domain.errors import DomainError


class ObjectiveKind(StrEnum):
    # Maximise expected success under the cap (docs/allocation.md#the-workload-cap), then the
    # shortest makespan.
    SUCCESS_THEN_MAKESPAN = "success_then_makespan"
    # The shortest makespan under the cap whose expected success is at least a floor.
    MAKESPAN = "makespan"


@dataclass(frozen=True)
class Objective:
    kind: ObjectiveKind = ObjectiveKind.SUCCESS_THEN_MAKESPAN
    min_expected_success: float = 0.0  # read only by MAKESPAN

    def __post_init__(self) -> None:
        try:
            kind = ObjectiveKind(self.kind)
        except ValueError:
            known = ", ".join(k.value for k in ObjectiveKind)
            raise DomainError(
                "objective", f"unknown objective {self.kind!r}; choose one of: {known}"
            ) from None
        object.__setattr__(self, "kind", kind)
        floor = self.min_expected_success
        if not (isinstance(floor, int | float) and math.isfinite(floor) and 0 <= floor <= 1):
            raise DomainError(
                "min_expected_success", f"must lie in [0, 1] (a mean success), got {floor!r}"
            )
        if floor > 0 and kind is not ObjectiveKind.MAKESPAN:
            raise DomainError(
                "min_expected_success",
                "applies to objective 'makespan' only; 'success_then_makespan' already "
                "maximises expected success",
            )

    @property
    def is_default(self) -> bool:
        return self == Objective()
