"""The facts of one decision, shared by the graph, its prompts and validation, and reasoners."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from app.domain.modes import Mode, Weights
from app.domain.phases import Phase

if TYPE_CHECKING:
    from app.domain.scheduling.progress import TimeOption


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
