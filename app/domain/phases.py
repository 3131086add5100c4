"""Workflow phases (paper Algorithm 1): where in the queue a decision is being made."""

from __future__ import annotations

from enum import StrEnum


class Phase(StrEnum):
    EARLY = "early"
    MIDDLE = "middle"
    LATE = "late"


def detect_phase(allocated: int, total: int) -> Phase:
    """p = allocated / total; early p < 0.33, middle p < 0.67, else late."""
    progress = allocated / total if total else 1.0
    if progress < 0.33:
        return Phase.EARLY
    if progress < 0.67:
        return Phase.MIDDLE
    return Phase.LATE


def balance_urgency(allocated: int, total: int) -> float:
    return allocated / total if total else 1.0
