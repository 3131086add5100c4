"""An allocation problem: an instance, an operational mode and the workload cap it implies."""

from __future__ import annotations

from dataclasses import dataclass

from app.domain.cap import WorkloadCap
from app.domain.errors import DomainError
from app.domain.models import Instance
from app.domain.modes import Mode, default_max_deviation


@dataclass(frozen=True)
class Problem:
    instance: Instance
    mode: Mode
    cap: WorkloadCap

    @classmethod
    def build(
        cls,
        instance: Instance,
        mode: Mode = Mode.BALANCED,
        max_deviation: float | None = None,
        *,
        uncapped: bool = False,
    ) -> Problem:
        """Apply the mode's default cap unless `max_deviation` overrides it (or `uncapped`
        asks for no cap at all); reject infeasible caps."""
        if uncapped:
            max_deviation = None
        elif max_deviation is None:
            max_deviation = default_max_deviation(mode, instance.n_tasks, instance.n_robots)
        elif max_deviation < 0:
            raise DomainError("max_deviation", f"must be >= 0 tasks, got {max_deviation:g}")
        cap = WorkloadCap(instance.n_tasks, instance.n_robots, max_deviation)
        cap.ensure_feasible()
        return cls(instance=instance, mode=mode, cap=cap)
