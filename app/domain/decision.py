"""The facts of one decision, shared by the graph, its prompts and validation, and reasoners."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from app.domain.modes import Mode, Weights
from app.domain.phases import Phase

if TYPE_CHECKING:
    from app.domain.scheduling.progress import TimeOption


# A team in unit order: the robot covering each unit of the task (docs/allocation.md#teams).
Members = tuple[int, ...]


@dataclass(frozen=True)
class TeamFacts:
    """The team side of a decision on a team task (docs/allocation.md#teams)."""

    units: tuple[str, ...]  # the features of the task's units, in the team's key order
    # Per feature (key order), per robot: its rate, or None where it may not cover the feature.
    rates: tuple[tuple[float | None, ...], ...]
    best: Members | None = None  # the best-success team the cap allows
    fewest: Members | None = None  # the least-loaded team the cap allows
    guided: Members | None = None  # the optimizer's team, when the run is guided
    # Why a team breaks the cap for the tasks after this one, or (timed) misses the task's
    # deadline or a member's shift: "members free in time" (None: it does neither).
    check: Callable[[Members], str | None] | None = field(default=None, compare=False)
    # A timed decision: what a team would make of the task in time (its start and end, the
    # last member to arrive); None untimed.
    timing: Callable[[Members], TimeOption] | None = field(default=None, compare=False)

    @property
    def features(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(self.units))

    def count(self, feature: str) -> int:
        return self.units.count(feature)

    def rate(self, feature: str, robot: int) -> float | None:
        return self.rates[self.features.index(feature)][robot]

    def success(self, members: Members) -> float:
        """The team's S: the mean over units of the covering member's rate."""
        rates = [self.rate(f, r) or 0.0 for f, r in zip(self.units, members, strict=True)]
        return sum(rates) / len(rates)

    def problem(self, members: Members) -> str | None:
        """The cap check, when there is one."""
        return None if self.check is None else self.check(members)


@dataclass(frozen=True)
class DecisionContext:
    """The true facts of one decision, for reasoners that compute rather than read prompts."""

    task_index: int
    total_tasks: int
    task_name: str
    features: tuple[str, ...]
    robot_names: tuple[str, ...]
    robot_labels: tuple[str, ...]
    success: tuple[float, ...]  # S per robot for this task
    loads: tuple[int, ...]  # before this decision
    target: float
    feasible: tuple[int, ...]  # robots whose choice keeps the cap satisfiable
    phase: Phase
    mode: Mode
    weights: Weights
    tier: int = 0  # 0 first try; 1-3 retry tiers
    guided_robot: int | None = None  # optimizer guidance, when enabled
    # With guidance: success points each robot would give away (None: cap forbids it).
    guided_costs: tuple[float | None, ...] | None = None
    task_type: str = ""
    load_bounds: tuple[int, int] | None = None  # final-load range the cap allows; None = no cap
    # 1-based attempt at this task (tiers stop at 3; attempts do not): the key, with
    # task_index, of a recorded reply, for reasoners that replay a run's record.
    attempt: int = 1
    # docs/estimates.md#using-the-estimates: per robot, what its rates for this task rest on when
    # they are not the configured ones ("dexterous learned on 37 reports"); empty: configured.
    rate_notes: tuple[str, ...] = ()
    # docs/schedules.md#the-prompt-in-time, a timed instance: per robot, when it would start and end
    # the task and whether that meets the deadline and its shift; empty untimed. `feasible` then
    # holds only robots that meet them too (unless none does: then time rules out no one).
    timing: tuple[TimeOption, ...] = ()
    zone: str | None = None  # the task's zone, on a timed instance with zones
    release: float = 0.0
    deadline: float | None = None
    # docs/schedules.md#links: the task's links in words, when any is typed (else empty: the
    # robots' starts already say what plain links allow).
    links: tuple[str, ...] = ()
    # Tasks allocated before this one (pins and decisions), when the graph does not decide
    # in queue order (a timed instance); None: task_index of them.
    allocated: int | None = None
    # docs/allocation.md#teams: per robot, may it take this task (skills, duration map)?
    # Empty: every robot may. An ineligible robot is never in `feasible`.
    eligible: tuple[bool, ...] = ()
    # docs/allocation.md#teams: set on a team task; `feasible` then holds the robots that may
    # still join a team (eligible, room under the cap), and the team itself is checked whole.
    team: TeamFacts | None = None

    @property
    def labels(self) -> tuple[str, ...]:
        """How prompts and replies name each robot: its label, else its key."""
        return tuple(
            label or name for label, name in zip(self.robot_labels, self.robot_names, strict=True)
        )


def percent(x: float) -> str:
    """A success probability as prompts and replies write it: 0.7 -> '70.0%'."""
    return f"{x * 100:.1f}%"


@dataclass(frozen=True)
class GuidedChoice:
    """Optimizer guidance for one decision: the robot to prefer and what each choice costs."""

    robot: int
    # Success points (sum of S x 100 over the rest of the queue) each robot would give away;
    # None where choosing it would make the cap unsatisfiable.
    costs: tuple[float | None, ...]
    # A team task (docs/allocation.md#teams): the optimal completion's team; `robot` is its
    # first member and `costs` is empty (a team's alternatives are teams, not robots).
    team: Members | None = None
