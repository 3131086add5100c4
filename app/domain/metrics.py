"""Quality measures of an allocation (docs/allocation.md#success-and-balance): success, balance,
fairness, simulation."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from app.domain.models import Instance
from app.domain.teams import Teams, team_success

DEFAULT_TRIALS = 1000


class Severity(StrEnum):
    LOW = "low"
    MODERATE = "moderate"
    HIGH = "high"
    CRITICAL = "critical"


def workload(assignment: Sequence[int], n_robots: int, teams: Teams | None = None) -> list[int]:
    """Tasks per robot; a team task counts once for each member (docs/allocation.md#teams)."""
    loads = [0] * n_robots
    for t, r in enumerate(assignment):
        if teams and t in teams:
            for member in teams[t]:
                loads[member] += 1
        else:
            loads[r] += 1
    return loads


def task_successes(
    instance: Instance, assignment: Sequence[int], teams: Teams | None = None
) -> np.ndarray:
    """S per task: the robot's S(r, t), or a team's mean over its units."""
    p = instance.success[np.arange(len(assignment)), np.asarray(assignment, dtype=int)]
    if teams:
        p = p.copy()
        for t, members in teams.items():
            p[t] = team_success(instance.tasks[t], instance.robots, members)
    return p


def max_abs_deviation(loads: Sequence[int], target: float) -> float:
    return max(abs(load - target) for load in loads)


def balance_score(loads: Sequence[int], target: float) -> float:
    """Paper Eq. 2, clamped: 100 * (1 - max|d_r| / W)."""
    if target <= 0:
        return 100.0
    return min(100.0, max(0.0, 100.0 * (1.0 - max_abs_deviation(loads, target) / target)))


def severity(loads: Sequence[int], target: float) -> Severity:
    x = max_abs_deviation(loads, target) / target if target > 0 else 0.0
    if x <= 0.25:
        return Severity.LOW
    if x <= 0.5:
        return Severity.MODERATE
    if x <= 1.0:
        return Severity.HIGH
    return Severity.CRITICAL


def jain_index(loads: Sequence[int]) -> float:
    squares = sum(x * x for x in loads)
    if squares == 0:
        return 1.0
    return sum(loads) ** 2 / (len(loads) * squares)


def expected_success(
    instance: Instance, assignment: Sequence[int], teams: Teams | None = None
) -> float:
    if teams:
        return float(np.mean(task_successes(instance, assignment, teams)))
    s = instance.success
    return float(np.mean([s[t, r] for t, r in enumerate(assignment)]))


def feature_success(
    instance: Instance, assignment: Sequence[int], teams: Teams | None = None
) -> dict[str, float]:
    s = task_successes(instance, assignment, teams)
    out: dict[str, float] = {}
    for feature in instance.features:
        values = [s[t] for t, task in enumerate(instance.tasks) if feature in task.features]
        out[feature] = float(np.mean(values))
    return out


@dataclass(frozen=True)
class Completion:
    mean: float
    ci95: tuple[float, float]
    trials: int


def simulate_completion(
    instance: Instance,
    assignment: Sequence[int],
    *,
    seed: int,
    trials: int = DEFAULT_TRIALS,
    teams: Teams | None = None,
) -> Completion:
    """K seeded Monte-Carlo executions; each task succeeds with probability S."""
    p = task_successes(instance, assignment, teams)
    rng = np.random.default_rng(seed)
    rates = (rng.random((trials, p.size)) < p).mean(axis=1)
    mean = float(rates.mean())
    half = 1.96 * float(rates.std(ddof=1)) / math.sqrt(trials) if trials > 1 else 0.0
    return Completion(mean, (max(0.0, mean - half), min(1.0, mean + half)), trials)


@dataclass(frozen=True)
class BalanceScope:
    """What balance is measured over when some robots are outside it (pins,
    docs/allocation.md#success-and-balance): the target W of the available fleet and the robots in
    the balance."""

    target: float
    robots: tuple[int, ...]

    def loads(self, loads: Sequence[int]) -> list[int]:
        return [loads[r] for r in self.robots]


@dataclass(frozen=True)
class Metrics:
    expected_success: float
    balance_score: float
    max_deviation: float
    imbalance_severity: Severity
    workload: dict[str, int]
    feature_success: dict[str, float]
    jain_index: float
    simulated_completion: Completion


def compute_metrics(
    instance: Instance,
    assignment: Sequence[int],
    *,
    seed: int = 0,
    trials: int = DEFAULT_TRIALS,
    scope: BalanceScope | None = None,
    teams: Teams | None = None,
) -> Metrics:
    """Success over every task; balance, deviation, severity and Jain over `scope` (the
    available robots and their W, see Problem.balance_scope), or the whole fleet. The
    workload lists every robot, including unavailable ones with their pins. `teams`: the
    members of each team task (docs/allocation.md#teams)."""
    loads = workload(assignment, instance.n_robots, teams)
    counted = loads if scope is None else scope.loads(loads)
    w = instance.target_load if scope is None else scope.target
    return Metrics(
        expected_success=expected_success(instance, assignment, teams),
        balance_score=balance_score(counted, w),
        max_deviation=max_abs_deviation(counted, w),
        imbalance_severity=severity(counted, w),
        workload={robot.name: load for robot, load in zip(instance.robots, loads, strict=True)},
        feature_success=feature_success(instance, assignment, teams),
        jain_index=jain_index(counted),
        simulated_completion=simulate_completion(
            instance, assignment, seed=seed, trials=trials, teams=teams
        ),
    )
