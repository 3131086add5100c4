"""Learning from the site (docs/estimates.md#the-model): Beta posteriors of success rates and
log-normal durations, computed from outcome counts; and the rates a run plans with when it asks for
learned (posterior means) or sampled (one Thompson draw) ones.

Pure arithmetic over counts: where the counts come from (the execution reports) is the
store's business (app.store.site_repository), what they are shown as is app.sites'.

Success: the prior of (site, robot, feature) is Beta(a0, b0) with mean = the configured
rate and a0 + b0 = the prior strength (pseudo-observations); s successes and f failures
give Beta(a0 + s, b0 + f). Its mean and the central 90% interval are reported.

Durations: log-normal. Durations are positive and skewed to the right, and their errors
are multiplicative (twice the plan is as plausible as half of it); the model's sufficient
statistics (n, the sum of ln d and of ln^2 d) add up in one SQL pass over any number of
reports and can be kept incrementally, where a median needs every value sorted and gives
no interval. The configured duration is the prior of the log-median, weighted like the
success prior; the 90% interval is for the median (Student t on the observed spread).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

DEFAULT_SITE = "default"
DEFAULT_PRIOR_STRENGTH = 10.0
CREDIBLE = 0.90
_TAIL = (1.0 - CREDIBLE) / 2


class RateSource(StrEnum):
    """Which success rates a run plans with."""

    CONFIGURED = "configured"  # the request's (the default: nothing changes unasked)
    LEARNED = "learned"  # posterior means from the site's reports
    SAMPLED = "sampled"  # one draw from each posterior (Thompson sampling: explores)


class DurationSource(StrEnum):
    CONFIGURED = "configured"
    LEARNED = "learned"


class Basis(StrEnum):
    """What one planned rate rests on."""

    CONFIGURED = "configured"  # asked for configured rates
    LEARNED = "learned"  # a posterior mean over at least one report
    SAMPLED = "sampled"  # a draw from the posterior
    PRIOR = "prior"  # learned or sampled asked, no report yet: the configured rate


@dataclass(frozen=True)
class Counts:
    successes: int = 0
    failures: int = 0

    @property
    def reports(self) -> int:
        return self.successes + self.failures

    def __add__(self, other: Counts) -> Counts:
        return Counts(self.successes + other.successes, self.failures + other.failures)


@dataclass(frozen=True)
class BetaEstimate:
    prior: float  # the prior mean (a configured rate)
    strength: float  # a0 + b0
    successes: int
    failures: int

    @property
    def alpha(self) -> float:
        return self.prior * self.strength + self.successes

    @property
    def beta(self) -> float:
        return (1.0 - self.prior) * self.strength + self.failures

    @property
    def reports(self) -> int:
        return self.successes + self.failures

    @property
    def mean(self) -> float:
        total = self.alpha + self.beta
        return self.prior if total <= 0 else self.alpha / total

    @property
    def interval(self) -> tuple[float, float]:
        """Central 90% credible interval. A prior of exactly 0 or 1 with nothing observed
        against it is a point mass (scipy's Beta needs both parameters positive)."""
        if self.alpha <= 0 or self.beta <= 0:
            return (self.mean, self.mean)
        # The Beta quantile from scipy.special (what stats.beta.ppf calls), imported here:
        # scipy.stats took 2.7 s to import on an idle machine and past an HTTP client's 5 s
        # under CI's load, in the first GET /sites/{site}/estimates; scipy.special 0.6 s.
        from scipy.special import betaincinv

        low, high = betaincinv(self.alpha, self.beta, [_TAIL, 1.0 - _TAIL])
        return (float(low), float(high))

    def draw(self, rng: np.random.Generator) -> float:
        if self.alpha <= 0 or self.beta <= 0:
            return self.mean
        return float(rng.beta(self.alpha, self.beta))


@dataclass(frozen=True)
class LogStats:
    """Sufficient statistics of observed durations (minutes), on the log scale."""

    n: int = 0
    sum_log: float = 0.0
    sum_log2: float = 0.0

    def __add__(self, other: LogStats) -> LogStats:
        return LogStats(
            self.n + other.n, self.sum_log + other.sum_log, self.sum_log2 + other.sum_log2
        )

    @classmethod
    def of(cls, minutes: Sequence[float]) -> LogStats:
        logs = [math.log(m) for m in minutes]
        return cls(len(logs), sum(logs), sum(x * x for x in logs))

    @property
    def mean_log(self) -> float | None:
        return None if self.n == 0 else self.sum_log / self.n

    @property
    def sd_log(self) -> float | None:
        """Sample standard deviation of ln d (None below two observations)."""
        if self.n < 2:
            return None
        variance = (self.sum_log2 - self.sum_log * self.sum_log / self.n) / (self.n - 1)
        return math.sqrt(max(variance, 0.0))


@dataclass(frozen=True)
class DurationEstimate:
    planned: float | None  # configured minutes (the prior's median); None: untimed runs
    observed: LogStats
    strength: float

    @property
    def observed_median(self) -> float | None:
        m = self.observed.mean_log
        return None if m is None else math.exp(m)

    @property
    def median(self) -> float | None:
        """Posterior log-median, back on the minute scale: the plan's figure weighted as
        `strength` observations, pooled with the observed ones."""
        m = self.observed.mean_log
        if self.planned is None or self.planned <= 0:
            return None if m is None else math.exp(m)
        mu0 = math.log(self.planned)
        if m is None:
            return self.planned
        n, k = self.observed.n, self.strength
        return math.exp((k * mu0 + n * m) / (k + n))

    @property
    def interval(self) -> tuple[float, float] | None:
        """90% interval of the median: the observed spread, shrunk by every observation
        behind the estimate (the prior's included); None until two are observed."""
        sd, median = self.observed.sd_log, self.median
        if sd is None or median is None:
            return None
        weight = self.observed.n + (self.strength if self.planned else 0.0)
        from scipy.special import stdtrit  # Student's t quantile, as in BetaEstimate.interval

        half = float(stdtrit(self.observed.n - 1, 1.0 - _TAIL)) * sd / math.sqrt(weight)
        return (median * math.exp(-half), median * math.exp(half))


@dataclass(frozen=True)
class PlannedRate:
    """One (robot, feature) rate a run planned with, and what it rests on."""

    configured: float
    used: float
    successes: int
    failures: int
    basis: Basis

    def as_json(self) -> dict[str, Any]:
        return {
            "configured": self.configured,
            "used": self.used,
            "successes": self.successes,
            "failures": self.failures,
            "basis": self.basis.value,
        }


def plan_rates(
    robots: Sequence[Mapping[str, Any]],
    counts: Mapping[tuple[str, str], Counts],
    *,
    source: RateSource,
    strength: float,
    only: Collection[str] | None = None,
    rng: np.random.Generator | None = None,
) -> dict[str, dict[str, PlannedRate]]:
    """The rate of every (robot, feature) a run plans with, robot by name. `robots` carry
    the configured rates (`success`); `only` limits learning to those robots (the others
    keep their configured rates); `rng` draws the sampled rates."""
    out: dict[str, dict[str, PlannedRate]] = {}
    for robot in robots:
        name = str(robot["name"])
        learn = source != RateSource.CONFIGURED and (only is None or name in only)
        rates: dict[str, PlannedRate] = {}
        for feature, configured in robot["success"].items():
            seen = counts.get((name, feature), Counts())
            estimate = BetaEstimate(float(configured), strength, seen.successes, seen.failures)
            if not learn:
                used, basis = float(configured), Basis.CONFIGURED
            elif seen.reports == 0:
                used, basis = float(configured), Basis.PRIOR
            elif source == RateSource.SAMPLED:
                assert rng is not None, "sampled rates need a random generator"
                used, basis = estimate.draw(rng), Basis.SAMPLED
            else:
                used, basis = estimate.mean, Basis.LEARNED
            rates[feature] = PlannedRate(
                float(configured), used, seen.successes, seen.failures, basis
            )
        out[name] = rates
    return out


def rates_record(
    planned: Mapping[str, Mapping[str, PlannedRate]],
    *,
    source: RateSource,
    site: str,
    as_of: str,
    strength: float,
    needed: Collection[str],
) -> dict[str, Any]:
    """What a run records of the rates it planned with (its first event and its stored
    request): every number, what it rests on, and each needed (robot, feature) that had no
    report and so fell back to the prior."""
    fallback = [
        {"robot": robot, "feature": feature}
        for robot, rates in planned.items()
        for feature, rate in rates.items()
        if rate.basis == Basis.PRIOR and feature in needed
    ]
    return {
        "source": source.value,
        "site": site,
        "as_of": as_of,
        "prior_strength": strength,
        "robots": {
            robot: {feature: rate.as_json() for feature, rate in rates.items()}
            for robot, rates in planned.items()
        },
        "fallback": fallback,
    }


def with_rates(
    robots: Sequence[Mapping[str, Any]], planned: Mapping[str, Mapping[str, PlannedRate]]
) -> list[dict[str, Any]]:
    """The robots (as instance JSON) with the planned rates in place of the configured."""
    out = []
    for robot in robots:
        rates = planned.get(str(robot["name"]), {})
        success = {f: rates[f].used if f in rates else v for f, v in robot["success"].items()}
        out.append({**robot, "success": success})
    return out


def configured_rates(
    robots: Sequence[Mapping[str, Any]], record: Mapping[str, Any] | None
) -> list[dict[str, Any]]:
    """The robots with their configured rates: a run that planned with learned ones keeps
    the configured ones in its record."""
    if not record:
        return [{**r, "success": dict(r["success"])} for r in robots]
    known = record.get("robots", {})
    out = []
    for robot in robots:
        rates = known.get(str(robot["name"]), {})
        success = {
            f: float(rates[f]["configured"]) if f in rates else v
            for f, v in robot["success"].items()
        }
        out.append({**robot, "success": success})
    return out


def rate_notes(record: Mapping[str, Any] | None) -> dict[str, dict[str, tuple[str, int]]]:
    """For the prompt: robot -> feature -> (basis, reports) of every rate that is not the
    configured one as asked (learned, sampled, or a prior standing in for them)."""
    if not record:
        return {}
    out: dict[str, dict[str, tuple[str, int]]] = {}
    for robot, rates in record.get("robots", {}).items():
        notes = {
            feature: (str(r["basis"]), int(r["successes"]) + int(r["failures"]))
            for feature, r in rates.items()
            if r["basis"] != Basis.CONFIGURED
        }
        if notes:
            out[robot] = notes
    return out


def sampling_seed(seed: int, reports: int) -> list[int]:
    """The seed of a run's Thompson draw: its own seed and how many reports the site had,
    so two runs made from the same record draw alike and a new report draws anew."""
    return [int(seed), int(reports)]


def plan_durations(
    tasks: Sequence[Mapping[str, Any]],
    robots: Sequence[str],
    observed: Mapping[tuple[str, str], LogStats],
    *,
    strength: float,
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The tasks (as instance JSON) with learned durations: each timed task's duration
    becomes a per-robot map of posterior medians, the configured minutes the prior of each
    (robot, task type); untimed tasks stay untimed (docs/schedules.md#the-model: then every task is
    untimed). Returns the tasks and the record of what changed."""
    out: list[dict[str, Any]] = []
    used: dict[str, dict[str, dict[str, Any]]] = {}
    for task in tasks:
        duration = task.get("duration")
        if duration is None:
            out.append(dict(task))
            continue
        kind = str(task.get("type") or "Custom")
        per_robot: dict[str, float] = {}
        for robot in robots:
            planned = duration.get(robot) if isinstance(duration, Mapping) else duration
            if planned is None:
                continue  # the robot may not take the task (docs/schedules.md#the-model)
            seen = observed.get((robot, kind), LogStats())
            estimate = DurationEstimate(float(planned), seen, strength)
            median = estimate.median
            per_robot[robot] = round(median if median is not None else float(planned), 3)
            used.setdefault(robot, {})[kind] = {
                "configured": float(planned),
                "used": per_robot[robot],
                "observed": seen.n,
            }
        out.append({**task, "duration": per_robot})
    applied = any(t.get("duration") is not None for t in tasks)
    record: dict[str, Any] = {"source": DurationSource.LEARNED.value, "applied": applied}
    if applied:
        record["robots"] = used
    else:
        record["why"] = (
            "the instance has no task durations (docs/schedules.md#the-model): "
            "nothing to learn into"
        )
    return out, record


@dataclass(frozen=True)
class SiteCounts:
    """What a run learns from: (robot, feature) outcome counts, (robot, task type) observed
    durations, and how many reports they come from."""

    outcomes: Mapping[tuple[str, str], Counts]
    durations: Mapping[tuple[str, str], LogStats]
    reports: int
