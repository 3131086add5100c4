"""The workload cap: every robot's final load must lie in [ceil(W - cap), floor(W + cap)].

With pins (docs/living-plans.md#pins) some robots may be unavailable: they keep the tasks pinned on
them but take no new task and stand outside the balance. `n_tasks` and `n_robots` are then the
tasks and robots *in the balance* (W = n_tasks / n_robots), while load vectors still have
one entry per robot of the fleet; the unavailable robots' entries are ignored.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from functools import cached_property

from app.domain.errors import InfeasibleCapError


def _exact(value: float) -> Fraction:
    # Decimal text, not binary float: a cap of 0.1 means one tenth of a task.
    return Fraction(str(value))


@dataclass(frozen=True)
class WorkloadCap:
    n_tasks: int  # tasks in the balance: W's numerator
    n_robots: int  # robots in the balance: W's denominator
    max_deviation: float | None
    # Robot indexes (into fleet-length load vectors) outside the balance: take no task.
    unavailable: frozenset[int] = frozenset()

    @property
    def fleet_size(self) -> int:
        """Length of a load vector: the balance's robots plus the unavailable ones."""
        return self.n_robots + len(self.unavailable)

    def balanced(self, loads: Sequence[int]) -> list[int]:
        """The entries of a fleet-length load vector that count for the balance."""
        if not self.unavailable:
            return list(loads)
        return [x for i, x in enumerate(loads) if i not in self.unavailable]

    @property
    def target(self) -> float:
        return self.n_tasks / self.n_robots

    @cached_property  # read in every solver's inner loop; Fraction arithmetic is slow
    def lower(self) -> int:
        if self.max_deviation is None:
            return 0
        w = Fraction(self.n_tasks, self.n_robots)
        return max(0, math.ceil(w - _exact(self.max_deviation)))

    @cached_property
    def upper(self) -> int:
        if self.max_deviation is None:
            return self.n_tasks
        w = Fraction(self.n_tasks, self.n_robots)
        return min(self.n_tasks, math.floor(w + _exact(self.max_deviation)))

    def infeasibility(self) -> str | None:
        """A sentence explaining why no allocation fits the cap, or None if one does."""
        lo, hi, r, n = self.lower, self.upper, self.n_robots, self.n_tasks
        w = f"{self.target:g}"
        if lo > hi:
            return (
                f"max_deviation={self.max_deviation:g} around the target load {w} leaves no "
                f"whole number of tasks for a robot (it would need at least {lo} and at most "
                f"{hi}); raise max_deviation"
            )
        if r * hi < n:
            return (
                f"max_deviation={self.max_deviation:g} lets each of the {r} robots take at most "
                f"{hi} tasks ({r * hi} in all), fewer than the {n} tasks queued; raise "
                "max_deviation"
            )
        if r * lo > n:
            return (
                f"max_deviation={self.max_deviation:g} requires each of the {r} robots to take "
                f"at least {lo} tasks ({r * lo} in all), more than the {n} tasks queued; "
                "raise max_deviation"
            )
        return None

    def ensure_feasible(self) -> None:
        reason = self.infeasibility()
        if reason is not None:
            raise InfeasibleCapError(reason)

    def can_complete(self, loads: Sequence[int], remaining: int) -> bool:
        """Can `remaining` more tasks be spread so every final load fits the cap?"""
        lo, hi = self.lower, self.upper
        if self.unavailable:
            loads = self.balanced(loads)
        if any(load > hi for load in loads):
            return False
        shortfall = sum(max(0, lo - load) for load in loads)
        room = sum(hi - load for load in loads)
        return shortfall <= remaining <= room

    def allows(self, loads: Sequence[int], robot: int, remaining_after: int) -> bool:
        """Does giving the current task to `robot` keep a cap-respecting completion possible?"""
        if robot in self.unavailable:
            return False
        after = list(loads)
        after[robot] += 1
        return self.can_complete(after, remaining_after)

    def feasible_robots(self, loads: Sequence[int], remaining_after: int) -> list[int]:
        return [r for r in range(len(loads)) if self.allows(loads, r, remaining_after)]

    def respected_by(self, loads: Sequence[int]) -> bool:
        return all(self.lower <= load <= self.upper for load in self.balanced(loads))


class CapTracker:
    """Loads placed so far, with O(1) "may this robot take the next task?" checks.

    Equivalent to WorkloadCap.allows for a queue processed in order, without rescanning
    every robot's load at every step (greedy on 10,000 x 50 needs this).
    """

    def __init__(
        self, cap: WorkloadCap, loads: Sequence[int] | None = None, remaining: int | None = None
    ) -> None:
        self.cap = cap
        self.loads = list(loads) if loads is not None else [0] * cap.fleet_size
        balanced = cap.balanced(self.loads)
        self.remaining = cap.n_tasks - sum(balanced) if remaining is None else remaining
        self.shortfall = sum(max(0, cap.lower - x) for x in balanced)
        # Per-robot ceiling; an unavailable robot's is below any load, so it never qualifies.
        self._ceiling = [-1 if i in cap.unavailable else cap.upper for i in range(len(self.loads))]

    def allows(self, robot: int) -> bool:
        load = self.loads[robot]
        if load + 1 > self._ceiling[robot]:
            return False
        shortfall = self.shortfall - (1 if load < self.cap.lower else 0)
        return shortfall <= self.remaining - 1

    def assign(self, robot: int) -> None:
        if self.loads[robot] < self.cap.lower:
            self.shortfall -= 1
        self.loads[robot] += 1
        self.remaining -= 1
