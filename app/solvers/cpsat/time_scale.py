"""Minutes as CP-SAT integers.

CP-SAT reasons over integers; the domain's minutes may be fractional. The scale is the
smallest of 1, 10, 100 or 1,000 units per minute that makes every time value of the
problem whole. If none does (e.g. a third of a minute), values are rounded at 1/1,000 of
a minute on the safe side (durations, travel, releases and shift starts up; deadlines and
shift ends down), so every integer schedule is feasible in minutes, and `exact` is False:
the solver then never calls its answer optimal nor its bound proven.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from app.domain.problem import Problem

_FACTORS = (1, 10, 100, 1000)
_TOLERANCE = 1e-9


@dataclass(frozen=True)
class TimeScale:
    units_per_minute: int
    exact: bool

    @classmethod
    def of(cls, problem: Problem) -> TimeScale:
        values = list(_time_values(problem))
        for factor in _FACTORS:
            if all(abs(v * factor - round(v * factor)) <= _TOLERANCE * max(1.0, v) for v in values):
                return cls(factor, True)
        return cls(_FACTORS[-1], False)

    def up(self, minutes: float) -> int:
        x = minutes * self.units_per_minute
        return round(x) if self.exact else math.ceil(x - _TOLERANCE)

    def down(self, minutes: float) -> int:
        x = minutes * self.units_per_minute
        return round(x) if self.exact else math.floor(x + _TOLERANCE)

    def minutes(self, units: float) -> float:
        return units / self.units_per_minute


def _time_values(problem: Problem) -> Iterable[float]:
    tm = problem.instance.timing
    for row in tm.durations:
        yield from (d for d in row if d is not None)
    for row in tm.travel_minutes:
        yield from row
    yield from tm.release
    yield from (a.lag for arcs in tm.links for a in arcs)
    yield from (d for d in tm.deadline if math.isfinite(d))
    for a, b in tm.shifts:
        yield a
        if math.isfinite(b):
            yield b
    yield from problem.pinned_starts.values()
    yield problem.not_before
