"""The free tasks as *units* on the available robots: what the exact solvers decide on an
instance with team tasks or eligibility restrictions (docs/allocation.md#teams).

A single-robot task is one choice among its eligible robots; a team task is one robot per
unit, distinct, each eligible for its unit's feature. The integer weights are the ones of
`app.solvers.tiebreak`, made exact for teams: a team of k units contributes the mean of its
members' rates, so every weight is multiplied by K = the lcm of the team sizes and a unit's
rate weighs K / k. Brute force, the DP and the min-cost flow then compare the same integers.
Robot order among equal plans: the members of one feature in robot order, earlier units
(task order, then unit order) on lower-numbered robots.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from app.domain.cap import WorkloadCap
from app.domain.problem import Problem
from app.domain.teams import covers
from app.solvers.base import Solution
from app.solvers.tiebreak import deviation_factor, weight_scale

# One choice for a task: the column (available robot) covering each unit, in unit order.
Members = tuple[int, ...]


def needs_units(problem: Problem) -> bool:
    """Does the problem need the unit view (teams, or robots some task may not take)?"""
    return problem.instance.has_teams or not problem.instance.eligible.all()


@dataclass(frozen=True)
class UnitView:
    problem: Problem
    tasks: tuple[int, ...]  # free task indexes, in queue order
    robots: tuple[int, ...]  # available robot indexes: the columns
    cap: WorkloadCap  # the problem's bounds over these columns
    initial_loads: tuple[int, ...]  # per column: the pins on it

    @classmethod
    def of(cls, problem: Problem) -> UnitView:
        cap = replace(problem.cap, unavailable=frozenset())
        loads = tuple(problem.initial_loads[r] for r in problem.available)
        return cls(problem, problem.free_tasks, problem.available, cap, loads)

    @property
    def n_robots(self) -> int:
        return len(self.robots)

    @cached_property
    def units(self) -> tuple[tuple[str, ...], ...]:
        """Per free task: its team's unit features; () for a single-robot task."""
        return tuple(self.problem.instance.units[t] for t in self.tasks)

    @cached_property
    def added(self) -> tuple[int, ...]:
        return tuple(len(u) or 1 for u in self.units)

    @cached_property
    def multiple(self) -> int:
        """K: the lcm of the team sizes, so a unit's share of its team's mean is whole."""
        return math.lcm(1, *(len(u) for u in self.units if u))

    @cached_property
    def scale(self) -> int:
        return weight_scale(self.cap.n_tasks, self.n_robots, len(self.tasks) * self.multiple)

    @cached_property
    def factor(self) -> int:
        return deviation_factor(self.cap.n_tasks, self.n_robots)

    @cached_property
    def single_weights(self) -> np.ndarray:
        """(free tasks, columns): K * round(S * scale), for single-robot tasks."""
        s = self.problem.instance.success[np.ix_(self.tasks, self.robots)]
        return np.rint(s * self.scale).astype(np.int64) * self.multiple

    def unit_weight(self, i: int, feature: str, col: int) -> int:
        rate = self.problem.instance.robots[self.robots[col]].success[feature]
        return int(np.rint(rate * self.scale)) * (self.multiple // len(self.units[i]))

    @cached_property
    def eligible(self) -> np.ndarray:
        return self.problem.instance.eligible[np.ix_(self.tasks, self.robots)]

    def single_columns(self, i: int) -> list[int]:
        return [c for c in range(self.n_robots) if self.eligible[i, c]]

    def unit_columns(self, i: int, feature: str) -> list[int]:
        """Columns that may cover a unit of `feature` of free task i."""
        robots = self.problem.instance.robots
        return [
            c
            for c in range(self.n_robots)
            if self.eligible[i, c] and covers(robots[self.robots[c]], feature)
        ]

    def options(self, i: int) -> list[tuple[Members, int]]:
        """Every choice for free task i with its integer weight, in robot order."""
        if not self.units[i]:
            w = self.single_weights[i]
            return [((c,), int(w[c])) for c in self.single_columns(i)]
        out = []
        for members in self._teams(i, 0, frozenset()):
            weight = sum(
                self.unit_weight(i, f, c) for f, c in zip(self.units[i], members, strict=True)
            )
            out.append((members, weight))
        return out

    def _teams(self, i: int, start: int, used: frozenset[int]) -> Iterator[Members]:
        units = self.units[i]
        if start == len(units):
            yield ()
            return
        feature = units[start]
        count = units.count(feature)
        free = [c for c in self.unit_columns(i, feature) if c not in used]
        for group in itertools.combinations(free, count):
            for rest in self._teams(i, start + count, used | set(group)):
                yield group + rest

    def increments(self, members: Members) -> tuple[int, ...]:
        loads = [0] * self.n_robots
        for c in members:
            loads[c] += 1
        return tuple(loads)

    def solution(self, choices: Sequence[Members], details: dict[str, object]) -> Solution:
        """The full answer from one choice per free task: fleet robots, teams, pins kept."""
        robots = self.robots
        firsts = [robots[m[0]] for m in choices]
        # A pinned team task keeps its pinned team (docs/living-plans.md#pins-in-allocate).
        teams = dict(self.problem.pinned_teams)
        teams.update(
            (t, tuple(robots[c] for c in m))
            for t, m, u in zip(self.tasks, choices, self.units, strict=True)
            if u
        )
        return Solution(self.problem.complete(firsts), teams=teams, details=dict(details))
