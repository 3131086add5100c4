"""Operational modes: strategic weights, default workload caps, trade-off thresholds."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from app.domain.phases import Phase


class Mode(StrEnum):
    SUCCESS_FOCUSED = "success_focused"
    BALANCED = "balanced"
    AGGRESSIVE_BALANCE = "aggressive_balance"


@dataclass(frozen=True)
class Weights:
    success: float
    balance: float

    def __str__(self) -> str:
        return f"{round(self.success * 100)}:{round(self.balance * 100)}"


_BALANCED_WEIGHTS = {
    Phase.EARLY: Weights(0.8, 0.2),
    Phase.MIDDLE: Weights(0.6, 0.4),
    Phase.LATE: Weights(0.4, 0.6),
}
_BALANCED_THRESHOLDS = {Phase.EARLY: 8.0, Phase.MIDDLE: 13.0, Phase.LATE: 18.0}

MODE_DESCRIPTIONS = {
    Mode.SUCCESS_FOCUSED: "maximise task success; balance is secondary (90:10)",
    Mode.BALANCED: "phase-adaptive: success first early (80:20), then 60:40, balance late (40:60)",
    Mode.AGGRESSIVE_BALANCE: "keep robots evenly loaded (30:70)",
}


def strategic_weights(mode: Mode, phase: Phase) -> Weights:
    if mode is Mode.SUCCESS_FOCUSED:
        return Weights(0.9, 0.1)
    if mode is Mode.AGGRESSIVE_BALANCE:
        return Weights(0.3, 0.7)
    return _BALANCED_WEIGHTS[phase]


def tradeoff_threshold(mode: Mode, phase: Phase) -> float:
    """Success gap (points) above which the best robot beats the least-loaded one."""
    if mode is Mode.SUCCESS_FOCUSED:
        return 8.0
    if mode is Mode.AGGRESSIVE_BALANCE:
        return 18.0
    return _BALANCED_THRESHOLDS[phase]


def default_max_deviation(mode: Mode, n_tasks: int, n_robots: int) -> int | None:
    """Tasks either side of W = n_tasks / n_robots a robot may end with; None means no cap.

    Integer arithmetic: ceil(W / 3) computed on floats can land one too high.
    """
    if mode is Mode.SUCCESS_FOCUSED:
        return None
    if mode is Mode.BALANCED:
        return -(-n_tasks // (3 * n_robots))
    return max(1, -(-n_tasks // (12 * n_robots)))
