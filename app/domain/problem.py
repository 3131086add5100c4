"""An allocation problem: an instance, an operational mode and the workload cap it implies.

Optionally with pins (docs/living-plans.md#pins-in-allocate): tasks fixed on robots, and robots that
are unavailable (they keep their pins, take no new task and stand outside the balance).
Then W = (free tasks + tasks pinned on available robots) / available robots, loads start
from the pins on available robots, and the cap's bounds apply to available robots only.
Tasks pinned on an unavailable robot count for expected success, not for loads.

On a timed instance (docs/schedules.md#the-model) a problem also carries its objective (see
`app.domain.objective` for why it lives here), the fixed starts of pinned tasks (tasks
reported started or done), and `not_before`: no task without a fixed start begins before
it (a revision's `now`). An untimed problem has none of these and is built as before.
A guided timed LTAA run also carries its guidance plan's starts (`decide_by`).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from functools import cached_property
from types import MappingProxyType

import numpy as np

from app.domain.cap import WorkloadCap
from app.domain.completion import CompletionMemo, TeamLeft, completable, units_completable
from app.domain.eligibility import check_time_arguments
from app.domain.errors import DomainError, InfeasibleCapError
from app.domain.metrics import BalanceScope
from app.domain.models import Instance
from app.domain.modes import Mode, default_max_deviation
from app.domain.objective import Objective
from app.domain.pins import checked_pinned_teams
from app.domain.teams import covers

_NO_PINS: Mapping[int, int] = MappingProxyType({})
_NO_STARTS: Mapping[int, float] = MappingProxyType({})
_NO_TEAMS: Mapping[int, tuple[int, ...]] = MappingProxyType({})
Later = Sequence[int] | None  # the free tasks still to decide; None: those after, in the queue
Order = bool | Sequence[int]  # queue order, no order (no completion check), or Later's tasks


@dataclass(frozen=True)
class Problem:
    instance: Instance
    mode: Mode
    cap: WorkloadCap
    # task index -> robot index, in task order; hash=False: a mapping is not hashable.
    pinned: Mapping[int, int] = field(default_factory=lambda: _NO_PINS, hash=False)
    unavailable: frozenset[int] = frozenset()
    objective: Objective = field(default_factory=Objective)
    # task index -> fixed start minute, for pinned tasks that started (timed only)
    pinned_starts: Mapping[int, float] = field(default_factory=lambda: _NO_STARTS, hash=False)
    not_before: float = 0.0  # minutes; no task without a fixed start begins earlier
    # task index -> its start in a guidance plan (timed, guided LTAA runs only): the graph
    # decides in this order instead of the earliest start (app.solvers.timed_guidance says why;
    # docs/schedules.md#the-order-of-decisions). Empty: the earliest-start order. Set with
    # dataclasses.replace, never by build().
    decide_by: Mapping[int, float] = field(default_factory=lambda: _NO_STARTS, hash=False)
    # docs/living-plans.md#teams-in-a-revision: task index -> the members (unit order) of a pinned
    # team task; its `pinned` robot is the first. Every available member carries the pin's load.
    pinned_teams: Mapping[int, tuple[int, ...]] = field(
        default_factory=lambda: _NO_TEAMS, hash=False
    )

    @classmethod
    def build(
        cls,
        instance: Instance,
        mode: Mode = Mode.BALANCED,
        max_deviation: float | None = None,
        *,
        uncapped: bool = False,
        pinned: Mapping[int, int] | None = None,
        unavailable: Iterable[int] = (),
        objective: Objective | None = None,
        pinned_starts: Mapping[int, float] | None = None,
        not_before: float = 0.0,
        pinned_teams: Mapping[int, Sequence[int]] | None = None,
    ) -> Problem:
        """Apply the mode's default cap (for the W of the available fleet) unless
        `max_deviation` overrides it (or `uncapped` asks for no cap at all); reject
        infeasible caps, including caps the pins already break. The time arguments are for
        timed instances only."""
        pins = _checked_pins(instance, pinned or {})
        teams = checked_pinned_teams(instance, pins, pinned_teams or {})
        off = _checked_unavailable(instance, unavailable)
        objective = objective or Objective()
        starts = check_time_arguments(
            instance, pins, off, objective, dict(pinned_starts or {}), not_before, teams=teams
        )
        n_available = instance.n_robots - len(off)
        # Loads count units (docs/allocation.md#teams): a team task once per member.
        added = instance.loads_added
        balance_tasks = sum(1 for t, r in pins.items() for m in teams.get(t, (r,)) if m not in off)
        balance_tasks += instance.n_units - sum(added[t] for t in pins)
        if uncapped:
            max_deviation = None
        elif max_deviation is None:
            max_deviation = default_max_deviation(mode, balance_tasks, n_available)
        elif max_deviation < 0:
            raise DomainError("max_deviation", f"must be >= 0 tasks, got {max_deviation:g}")
        cap = WorkloadCap(balance_tasks, n_available, max_deviation, off)
        problem = cls(
            instance=instance,
            mode=mode,
            cap=cap,
            pinned=MappingProxyType(pins),
            unavailable=off,
            objective=objective,
            pinned_starts=MappingProxyType(starts),
            not_before=float(not_before),
            pinned_teams=MappingProxyType(teams),
        )
        if pins or off:
            problem._ensure_formable()
            problem._ensure_completable()
        else:
            cap.ensure_feasible()
        return problem

    # -- the pinned view -------------------------------------------------------------------

    @cached_property
    def available(self) -> tuple[int, ...]:
        """Robot indexes that may take new tasks, in fleet order."""
        return tuple(r for r in range(self.instance.n_robots) if r not in self.unavailable)

    @cached_property
    def free_tasks(self) -> tuple[int, ...]:
        """Unpinned task indexes, in queue order: what a solver decides."""
        if not self.pinned:
            return tuple(range(self.instance.n_tasks))
        return tuple(t for t in range(self.instance.n_tasks) if t not in self.pinned)

    @cached_property
    def initial_loads(self) -> tuple[int, ...]:
        """Per robot of the fleet: the pins on it if available, 0 if unavailable."""
        loads = [0] * self.instance.n_robots
        for task, robot in self.pinned.items():
            for member in self.pinned_teams.get(task, (robot,)):
                if member not in self.unavailable:
                    loads[member] += 1
        return tuple(loads)

    @cached_property
    def free_units(self) -> int:
        """What the free tasks add to the loads: their count, a team task once per unit."""
        added = self.instance.loads_added
        return sum(added[t] for t in self.free_tasks)

    def feasible_robots(
        self, task_index: int, loads: Sequence[int], remaining: int, *, in_order: Order = True
    ) -> list[int]:
        """Robots that may take task `task_index` and keep the cap satisfiable. With
        eligibility restrictions (docs/allocation.md#teams) only eligible robots, and when the
        free tasks are placed in queue order (`in_order`) only those after whose choice every
        later free task still gets an eligible robot within the cap (`in_order` may list the
        free tasks still to decide, when a timed team run decides them in time order)."""
        eligible = self.instance.eligible
        if self.instance.has_teams:
            return self._unit_feasible(task_index, loads, in_order=in_order)
        robots = self.cap.feasible_robots(loads, remaining)
        if eligible.all():
            return robots
        robots = [r for r in robots if eligible[task_index, r]]
        if not in_order:
            return robots
        later = self.free_tasks[bisect.bisect_right(self.free_tasks, task_index) :]
        rows = eligible[np.ix_(later, self.available)]
        out = []
        for r in robots:
            after = list(loads)
            after[r] += 1
            balanced = [after[c] for c in self.available]
            if completable(rows, balanced, self.cap.lower, self.cap.upper):
                out.append(r)
        return out

    def _unit_feasible(
        self, task_index: int, loads: Sequence[int], *, in_order: Order
    ) -> list[int]:
        """feasible_robots on an instance with team tasks, where loads count units. For a team
        task: the robots that may join its team (eligible, with room under the cap); the
        team is then checked whole (`team_problem`)."""
        eligible = self.instance.eligible[task_index]
        upper = self.cap.upper
        robots = [r for r in self.available if eligible[r] and loads[r] < upper]
        if self.instance.units[task_index] or in_order is False:
            return robots
        later = None if in_order is True else in_order
        out = []
        for r in robots:
            after = list(loads)
            after[r] += 1
            if self.completes_after(task_index, after, later):
                out.append(r)
        return out

    @cached_property
    def _team_left(self) -> dict[int, TeamLeft]:
        """Per team task: per feature, its count and the available robots that may cover it."""
        inst, cols = self.instance, self.available
        out: dict[int, TeamLeft] = {}
        for t, units in enumerate(inst.units):
            if units:
                out[t] = [
                    (
                        units.count(f),
                        np.array([covers(inst.robots[c], f) for c in cols])
                        & inst.eligible[t, list(cols)],
                    )
                    for f in dict.fromkeys(units)
                ]
        return out

    def completes_after(
        self, task_index: int, loads_after: Sequence[int], later: Later = None
    ) -> bool:
        """Can every free task after `task_index` (every unit of a team) still get a distinct
        eligible robot within the cap, from `loads_after` (docs/allocation.md#teams)? `later`:
        the tasks still to decide, when they are not those after it in the queue."""
        balanced = tuple(loads_after[c] for c in self.available)

        def compute() -> bool:
            left = later
            if left is None:
                left = self.free_tasks[bisect.bisect_right(self.free_tasks, task_index) :]
            units = self.instance.units
            rows = self.instance.eligible[np.ix_([t for t in left if not units[t]], self.available)]
            teams = [self._team_left[t] for t in left if units[t]]
            return units_completable(rows, teams, balanced, self.cap.lower, self.cap.upper)

        return self._completion_memo.answer(task_index, later, balanced, compute)

    @cached_property
    def _completion_memo(self) -> CompletionMemo:
        return CompletionMemo()

    def team_problem(
        self, task_index: int, loads: Sequence[int], members: Sequence[int], later: Later = None
    ) -> str | None:
        """Why giving team task `task_index` to `members` breaks the cap (None: it does not)."""
        names = self.instance.robots
        after = list(loads)
        for r in members:
            if r in self.unavailable:
                return f"{names[r].display} is unavailable"
            after[r] += 1
            if after[r] > self.cap.upper:
                return (
                    f"{names[r].display} would carry {after[r]} tasks, above the cap's "
                    f"{self.cap.upper}"
                )
        if not self.completes_after(task_index, after, later):
            return (
                "this team would make the workload cap infeasible for the tasks after it "
                "(some later task could no longer get eligible robots within "
                f"[{self.cap.lower}, {self.cap.upper}] tasks per robot)"
            )
        return None

    def remaining_after(self, task_index: int) -> int:
        """Free tasks after `task_index` in the queue."""
        return len(self.free_tasks) - bisect.bisect_right(self.free_tasks, task_index)

    def allocated_before(self, task_index: int) -> int:
        """Pins plus free tasks before `task_index`: the phase rule's count
        (docs/living-plans.md#balance-and-phases)."""
        return len(self.pinned) + bisect.bisect_left(self.free_tasks, task_index)

    @property
    def target(self) -> float:
        """W of the available fleet (n_tasks / n_robots without pins)."""
        return self.cap.target

    @cached_property
    def balance_scope(self) -> BalanceScope | None:
        """What the metrics measure balance over; None means the whole fleet (no pins)."""
        if not self.pinned and not self.unavailable:
            return None
        return BalanceScope(target=self.cap.target, robots=self.available)

    def complete(self, choices: Sequence[int]) -> list[int]:
        """A full assignment from one robot per free task (in `free_tasks` order)."""
        if len(choices) != len(self.free_tasks):
            raise ValueError(
                f"{len(choices)} robots for {len(self.free_tasks)} free tasks; one each"
            )
        if not self.pinned:
            return list(choices)
        assignment = [0] * self.instance.n_tasks
        for task, robot in self.pinned.items():
            assignment[task] = robot
        for task, robot in zip(self.free_tasks, choices, strict=True):
            assignment[task] = robot
        return assignment

    # -- validation ------------------------------------------------------------------------

    def _ensure_formable(self) -> None:
        """With team tasks (docs/living-plans.md#teams-in-a-revision): every free team task can
        still be formed from the available robots, each unit by a distinct robot that may cover
        it, and all of them together within the cap; else a 422 naming the task and feature."""
        inst = self.instance
        if not inst.has_teams:
            return
        robots = inst.robots
        off = [robots[r].name for r in sorted(self.unavailable)]
        gone = f", with {', '.join(off)} unavailable" if off else ""
        for t in self.free_tasks:
            units = inst.units[t]
            for f in dict.fromkeys(units):
                need = units.count(f)
                able = [
                    robots[r].name
                    for r in self.available
                    if inst.eligible[t, r] and covers(robots[r], f)
                ]
                if len(able) < need:
                    can = f"only {len(able)} can ({', '.join(able)})" if able else "none can"
                    raise DomainError(
                        f"tasks.{t}.team.{f}",
                        f"task {inst.tasks[t].id!r} needs {need} distinct robots for '{f}' "
                        f"at once, and of the available robots {can}{gone}; make a robot that "
                        f"covers '{f}' available again, add one, or remove the task",
                        code="team_unformable",
                    )
        if not self.completes_after(-1, self.initial_loads):
            raise InfeasibleCapError(
                "the free tasks' teams cannot all be formed within the workload cap "
                f"[{self.cap.lower}, {self.cap.upper}] tasks per available robot{gone}, "
                "given the pins; raise max_deviation or make a robot available again",
                field="pinned",
            )

    def _ensure_completable(self) -> None:
        cap, free = self.cap, self.free_units
        if cap.can_complete(self.initial_loads, free):
            return
        suggestion = smallest_completing_cap(cap, self.initial_loads, free)
        reason = cap.infeasibility()
        where = "max_deviation"
        if reason is None:
            where = "pinned"
            reason = self._pin_conflict()
        raise InfeasibleCapError(
            f"{reason}; the smallest max_deviation that admits a completion given the pins "
            f"and unavailable robots is {suggestion:g}",
            field=where,
            suggested_max_deviation=suggestion,
        )

    def _pin_conflict(self) -> str:
        cap, loads, names = self.cap, self.initial_loads, self.instance.robots
        lo, hi, w = cap.lower, cap.upper, f"{cap.target:g}"
        bounds = f"[{lo}, {hi}] tasks around the target load {w} of the available robots"
        over = [r for r in self.available if loads[r] > hi]
        if over:
            r = over[0]
            return (
                f"the pins already put {loads[r]} tasks on robot '{names[r].name}', above the "
                f"cap's {bounds}"
            )
        free = self.free_units
        short = sum(max(0, lo - loads[r]) for r in self.available)
        if short > free:
            return (
                f"the pins leave {free} free tasks, but the available robots need {short} "
                f"more to reach the cap's {bounds}"
            )
        room = sum(hi - loads[r] for r in self.available)
        return (
            f"the pins leave {free} free tasks, but the available robots have room for only "
            f"{room} more within the cap's {bounds}"
        )


def smallest_completing_cap(cap: WorkloadCap, loads: Sequence[int], remaining: int) -> float:
    """The smallest max_deviation whose bounds let `remaining` tasks complete `loads`.

    The bounds [ceil(W - c), floor(W + c)] only change where W +- c crosses an integer,
    i.e. at c = |k - W| = |k*R - n| / R: multiples of 1/R. Feasibility only grows with c,
    so a binary search over those points finds the least; it is rounded up to three
    decimals (still below the next point, since 1/R >= 1/100), so it reads as typed.
    """
    n, r = cap.n_tasks, cap.n_robots
    points = sorted({Fraction(abs(k * r - n), r) for k in range(n + 1)} | {Fraction(0)})
    balanced = cap.balanced(loads)

    def fits(c: Fraction) -> bool:
        w = Fraction(n, r)
        lo, hi = max(0, math.ceil(w - c)), min(n, math.floor(w + c))
        if any(x > hi for x in balanced):
            return False
        return sum(max(0, lo - x) for x in balanced) <= remaining <= sum(hi - x for x in balanced)

    left, right = 0, len(points) - 1  # the largest point allows every load up to n: fits
    while left < right:
        mid = (left + right) // 2
        if fits(points[mid]):
            right = mid
        else:
            left = mid + 1
    best = points[left]
    if best.denominator == 1:
        return int(best)
    return math.ceil(best * 1000) / 1000


def _checked_pins(instance: Instance, pinned: Mapping[int, int]) -> dict[int, int]:
    pins: dict[int, int] = {}
    for task, robot in sorted(pinned.items()):
        if not 0 <= task < instance.n_tasks:
            raise DomainError(
                "pinned", f"task index {task} is outside the queue of {instance.n_tasks} tasks"
            )
        if not 0 <= robot < instance.n_robots:
            raise DomainError(
                "pinned",
                f"robot index {robot} (pin of task {instance.tasks[task].id!r}) is outside "
                f"the fleet of {instance.n_robots} robots",
            )
        pins[task] = robot
    return pins


def _checked_unavailable(instance: Instance, unavailable: Iterable[int]) -> frozenset[int]:
    off = frozenset(unavailable)
    for robot in sorted(off):
        if not 0 <= robot < instance.n_robots:
            raise DomainError(
                "unavailable",
                f"robot index {robot} is outside the fleet of {instance.n_robots} robots",
            )
    if len(off) == instance.n_robots:
        raise DomainError(
            "unavailable",
            "every robot is unavailable; no robot is left to take the unpinned tasks",
            code="no_robot_left",
        )
    return off
