"""A timed run's decision in time (docs/schedules.md#what-a-decision-records), on GET /runs/{id}
assignments and in the trace: absent on untimed runs, so their answers are unchanged."""

from __future__ import annotations

from datetime import timedelta
from typing import Any

from pydantic import BaseModel, Field

from app.domain.models import Instance


def _absent(value: object) -> bool:
    return value is None


class DecisionTimes(BaseModel):
    start: float | None = Field(
        None, description="Timed runs: start, minutes from the plan's start", exclude_if=_absent
    )
    end: float | None = Field(None, description="Timed runs: end, minutes", exclude_if=_absent)
    start_at: str | None = Field(
        None, description="Timed runs: start on the wall clock (RFC 3339)", exclude_if=_absent
    )
    end_at: str | None = Field(
        None, description="Timed runs: end on the wall clock (RFC 3339)", exclude_if=_absent
    )
    zone: str | None = Field(None, description="Timed runs: the task's zone", exclude_if=_absent)
    travel: float | None = Field(
        None, description="Timed runs: minutes travelled just before the task", exclude_if=_absent
    )
    seq: int | None = Field(
        None,
        description="Timed runs: the decision's place in the order the graph decided (time "
        "order, not queue order)",
        exclude_if=_absent,
    )
    later_by: float | None = Field(
        None,
        description="Timed runs: the trade-off in minutes, how much later this choice ends "
        "than the earliest end a robot allowed by the cap, deadline and shift offered",
        exclude_if=_absent,
    )


def decision_times(instance: Instance, decision: Any) -> dict[str, Any]:
    """The DecisionTimes fields of a stored decision (a row or a DecisionRecord)."""
    start, end = decision.start, decision.end
    if start is None or end is None:
        return {}
    origin = instance.timing.start if instance.timed else None

    def wall(minute: float) -> str | None:
        return None if origin is None else (origin + timedelta(minutes=minute)).isoformat()

    return {
        "start": start,
        "end": end,
        "start_at": wall(start),
        "end_at": wall(end),
        "zone": decision.zone,
        "travel": decision.travel,
        "seq": decision.seq,
        "later_by": decision.later_by,
    }
