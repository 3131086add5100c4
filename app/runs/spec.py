"""What a durable run was asked to do, stored as JSON so a restart can rebuild it exactly."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Collection, Mapping
from dataclasses import asdict, dataclass, field, replace
from datetime import datetime
from enum import Enum
from functools import cached_property
from typing import Any, Generic, TypeVar

import numpy as np

from app.domain import estimates
from app.domain.estimates import DEFAULT_SITE, DurationSource, RateSource
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.objective import ObjectiveKind
from app.domain.problem import Problem
from app.domain.review import ReviewPolicy
from app.domain.serialize import instance_to_dict, problem_from_dict
from app.reasoners.scope import DEFAULT_LLM_MARGIN, LLMScope

DEFAULT_QUALITY_THRESHOLD = 0.6
DEFAULT_MAX_RETRIES = 3


@dataclass(frozen=True)
class RunParameter:
    """One parameter a POST /runs body may name besides its instance: the request schema
    (RunRequest.to_order), the run order, the run spec (app.runs.service.spec_for), the run
    row and its `created` event, and a replay's check of what it repeats all read this
    table, so a new parameter is added here once."""

    name: str
    # The spec stores the order's value as sent (an enum by its value); otherwise the run
    # service resolves it (a server default, the mode's cap, the review policy...).
    copied: bool = True
    # A replay may name it, and must then send its source's value (app.runs.replay_source).
    repeatable: bool = True
    # Shown in the run's first event (`created`, or `revised`) and kept in its row.
    shown: bool = False


RUN_PARAMETERS: tuple[RunParameter, ...] = (
    RunParameter("reasoner", copied=False, repeatable=False, shown=True),
    RunParameter("mode", copied=False, shown=True),
    RunParameter("max_deviation", copied=False),
    RunParameter("quality_threshold"),
    RunParameter("max_retries"),
    RunParameter("guidance"),
    RunParameter("seed"),
    RunParameter("model"),
    RunParameter("temperature"),
    RunParameter("token_budget", copied=False),
    RunParameter("llm_scope", copied=False),
    RunParameter("llm_margin", copied=False),
    RunParameter("review", copied=False),
    RunParameter("site"),
    RunParameter("rates"),
    RunParameter("durations"),
    RunParameter("objective", copied=False, repeatable=False),
    RunParameter("min_expected_success", copied=False, repeatable=False),
)
# A run order's fields that name its instance (and, for a replay, its source run).
ORDER_INSTANCE_FIELDS = ("scenario", "tasks", "robots", "travel", "start", "replay_of")


def stored(value: Any) -> Any:
    """A parameter's value as a run spec stores it (JSON: an enum by its value)."""
    return value.value if isinstance(value, Enum) else value


def copied_parameters(order: RunOrder) -> dict[str, Any]:
    """The order's parameters that its run spec takes as sent."""
    return {p.name: stored(getattr(order, p.name)) for p in RUN_PARAMETERS if p.copied}


def repeated_parameters(order: RunOrder) -> dict[str, Any]:
    """What a replay request named of the parameters a replay may repeat, as a run spec
    stores them (each must equal its source's)."""
    return {
        p.name: stored(getattr(order, p.name))
        for p in RUN_PARAMETERS
        if p.repeatable and p.name in order.sent
    }


# The order resolved: what the worker replays on every resume, stored as the run's request
# (why a run has five shapes: app.runs.schemas.RunRequest).
@dataclass(frozen=True)
class RunSpec:
    instance_data: dict[str, Any]
    mode: str = Mode.BALANCED.value
    max_deviation: float | None = None  # the effective cap; None = no cap
    seed: int = 0
    reasoner: str = "rules"
    quality_threshold: float = DEFAULT_QUALITY_THRESHOLD
    max_retries: int = DEFAULT_MAX_RETRIES
    model: str | None = None
    temperature: float | None = None
    guidance: str | None = None
    # LLM tokens (input + output) the run may spend; once spent, the remaining tasks go to
    # the offline rules reasoner. None = no budget.
    token_budget: int | None = None
    # reasoner 'replay': the finished run whose recorded replies are replayed.
    replay_of: str | None = None
    # 'contested': an LLM reasoner is asked only for contested decisions, the rules
    # reasoner answers the clear-cut ones (app.reasoners.scope). Specs stored before these
    # existed read as the paper's 'all'.
    llm_scope: str = LLMScope.ALL.value
    llm_margin: float = DEFAULT_LLM_MARGIN
    # Whether max_deviation was asked for (kept by a revision) or the mode's default
    # (recomputed for a revision's W); None for runs stored before it was recorded.
    cap_explicit: bool | None = None
    # Revisions (docs/living-plans.md#pins): task index (as text, JSON keys) -> robot index of the
    # pins, robot indexes that take no new task, and the run revised.
    pinned: dict[str, int] | None = None
    unavailable: list[int] | None = None
    revision_of: str | None = None
    # docs/living-plans.md#teams-in-a-revision: task index (as text) -> robot indexes of a pinned
    # team task's members in unit order (the first is its `pinned` robot). None: no team pinned.
    pinned_teams: dict[str, list[int]] | None = None
    # Time in a revision (docs/living-plans.md#a-revision-in-time): task index (as text) -> the
    # fixed start minute of a pinned task reported started or done, and the revision's `now` in
    # minutes (nothing else starts earlier). None on every untimed run and every run that is not a
    # revision.
    pinned_starts: dict[str, float] | None = None
    not_before: float | None = None
    # app.domain.review.ReviewPolicy as JSON; None: no review.
    review: dict[str, Any] | None = None
    # Learning from the site (docs/estimates.md#using-the-estimates): the site, which rates and
    # durations the run plans with, and what learning put into instance_data
    # (app.domain.estimates.rates_record: every number, with the configured rate and the reports
    # behind it; None: configured).
    site: str = DEFAULT_SITE
    rates: str = RateSource.CONFIGURED.value
    durations: str = DurationSource.CONFIGURED.value
    learned: dict[str, Any] | None = None
    # docs/schedules.md#the-model, timed instances: the objective (app.domain.objective); specs
    # stored before it existed read as the default.
    objective: str = ObjectiveKind.SUCCESS_THEN_MAKESPAN.value
    min_expected_success: float = 0.0
    # How the run asks its model (docs/reasoners.md#structured-replies) and after how many
    # failed tasks in a row it stops asking (docs/reasoners.md#bounded-cost): the server's
    # settings when the run was created, so a resume, a replay and a revision ask and read
    # replies the same way. Specs stored before these existed asked in markdown and never
    # gave up.
    reply_format: str = "markdown"
    llm_give_up_after: int = 0

    @property
    def review_policy(self) -> ReviewPolicy | None:
        return None if self.review is None else ReviewPolicy.from_json(self.review)

    @classmethod
    def for_instance(cls, instance: Instance, **params: Any) -> RunSpec:
        """Without `max_deviation`, the mode's default cap is stored (None stores no cap)."""
        if "max_deviation" not in params:
            mode = Mode(params.get("mode", Mode.BALANCED.value))
            params["max_deviation"] = Problem.build(instance, mode).cap.max_deviation
        return cls(instance_data=instance_to_dict(instance), **params)

    @cached_property
    def problem(self) -> Problem:
        # One call into the domain (app.domain.serialize.problem_from_dict): the instance,
        # the objective and the problem are built there.
        return problem_from_dict(
            self.instance_data,
            self.mode,
            self.max_deviation,
            objective=self.objective,
            min_expected_success=self.min_expected_success,
            uncapped=self.max_deviation is None,
            pinned={int(t): r for t, r in (self.pinned or {}).items()},
            unavailable=self.unavailable or (),
            pinned_starts={int(t): m for t, m in (self.pinned_starts or {}).items()},
            not_before=self.not_before or 0.0,
            pinned_teams={int(t): m for t, m in (self.pinned_teams or {}).items()},
        )

    def with_site_estimates(
        self,
        totals: estimates.SiteCounts,
        *,
        strength: float,
        as_of: str,
        source: RateSource | None = None,
        only: Collection[str] | None = None,
    ) -> RunSpec:
        """This run planning with the site's estimates (docs/estimates.md#using-the-estimates) as
        its `rates` and `durations` ask (or `source` for the robots in `only`): the numbers go into
        the instance, the configured rates and the counts behind each number into `learned`."""
        source = source or RateSource(self.rates)
        robots = estimates.configured_rates(self.instance_data["robots"], self.learned)
        rng = (
            np.random.default_rng(estimates.sampling_seed(self.seed, totals.reports))
            if source == RateSource.SAMPLED
            else None
        )
        planned = estimates.plan_rates(
            robots, totals.outcomes, source=source, strength=strength, only=only, rng=rng
        )
        tasks = self.instance_data["tasks"]
        record = estimates.rates_record(
            planned,
            source=source,
            site=self.site,
            as_of=as_of,
            strength=strength,
            needed={f for t in tasks for f in t["features"]},
        )
        record["reports"] = totals.reports
        if self.durations == DurationSource.LEARNED:
            names = [str(r["name"]) for r in robots]
            tasks, record["durations"] = estimates.plan_durations(
                tasks, names, totals.durations, strength=strength
            )
        data = {
            **self.instance_data,
            "tasks": tasks,
            "robots": estimates.with_rates(robots, planned),
        }
        return replace(self, instance_data=data, learned=record)

    def created_detail(self, problem: Problem) -> dict[str, Any]:
        """What the run's first event says of it: the parameters the table shows, the
        instance's size, the cap it runs with, its site and learned numbers."""
        shown = {p.name: getattr(self, p.name) for p in RUN_PARAMETERS if p.shown}
        return {
            **shown,
            "tasks": problem.instance.n_tasks,
            "robots": problem.instance.n_robots,
            "max_deviation": problem.cap.max_deviation,
            **self.site_detail(),
        }

    def site_detail(self) -> dict[str, Any]:
        """What a run's first event says of its site and the learned numbers it plans with."""
        detail: dict[str, Any] = {"site": self.site}
        if self.learned is not None:
            detail |= {"rates": self.rates, "durations": self.durations, "learned": self.learned}
        return detail

    @property
    def rate_notes(self) -> Mapping[str, Mapping[str, tuple[str, int]]]:
        """Robot -> feature -> (basis, reports) of the rates that are not the configured
        ones, for the prompt (app.graph.prompts)."""
        return estimates.rate_notes(self.learned)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> RunSpec:
        return cls(**data)


# Why a run has five shapes: app.runs.schemas.RunRequest.
@dataclass(frozen=True)
class RunOrder:
    """What a POST /runs body asks for, nothing resolved yet: the instance as sent (a
    built-in scenario's name, or tasks and robots), the run's parameters, and which fields
    the request named. The run service turns it into a RunSpec (app.runs.service.submit_run):
    the server's defaults, a replay's copy of its source, the LLM scope and the review
    policy are resolved there."""

    scenario: str | None = None
    tasks: tuple[Task, ...] | None = None
    robots: tuple[Robot, ...] | None = None
    reasoner: str | None = None  # None: the server's default
    replay_of: str | None = None
    mode: Mode = Mode.BALANCED
    max_deviation: float | None = None
    seed: int = 0
    quality_threshold: float = DEFAULT_QUALITY_THRESHOLD
    max_retries: int = DEFAULT_MAX_RETRIES
    model: str | None = None
    temperature: float | None = None
    guidance: str | None = None
    token_budget: int | None = None  # None: the server's setting
    llm_scope: str | None = None  # None: the paper's 'all'
    llm_margin: float | None = None
    review: dict[str, Any] | None = None  # as sent (app.domain.review.ReviewPolicy JSON)
    site: str = DEFAULT_SITE
    rates: RateSource = RateSource.CONFIGURED
    durations: DurationSource = DurationSource.CONFIGURED
    # docs/schedules.md#the-model, timed instances: travel between zones, the wall-clock time of
    # minute 0 (None: the request's arrival), and the objective.
    travel: Mapping[str, Mapping[str, float]] | None = None
    start: datetime | None = None
    objective: ObjectiveKind = ObjectiveKind.SUCCESS_THEN_MAKESPAN
    min_expected_success: float = 0.0
    # The fields the request named: an explicit null max_deviation means no cap, and a
    # replay must repeat its source's value in every field it names.
    sent: frozenset[str] = field(default_factory=frozenset)


T = TypeVar("T")


class LruCache(Generic[T]):
    """A small thread-safe LRU of what never changes once a run has it (its parsed
    request; a completed run's metrics), keyed by run id: run ids are never reused."""

    def __init__(self, size: int) -> None:
        self._size = size
        self._items: OrderedDict[str, T] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: str) -> T | None:
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return self._items[key]
        return None

    def get_or_load(self, key: str, load: Callable[[], T]) -> T:
        cached = self.get(key)
        if cached is not None:
            return cached
        value = load()
        self.put(key, value)
        return value

    def put(self, key: str, value: T) -> None:
        with self._lock:
            self._items[key] = value
            self._items.move_to_end(key)
            while len(self._items) > self._size:
                self._items.popitem(last=False)
