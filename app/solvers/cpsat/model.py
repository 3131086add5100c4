"""The CP-SAT model of a timed problem: a flexible job shop with travel and a load cap.

Per task: a start and an end; per (task, robot that may take it) a presence literal and an
optional fixed-size interval on the task's start; exactly one presence per task. Per robot
a `NoOverlap` over its optional intervals, always: it is what makes CP-SAT fast. Travel
between zones (`Travel.PAIRS`): for each two tasks in different zones that a robot may
both take, an order literal; whichever goes first, the other starts no earlier than its
end plus the travel between their zones (where precedence fixes the order, the one
constraint without a literal). The first task starts no earlier than the shift start
plus the travel from the robot's start zone. This is exact because travel obeys the
triangle inequality (the domain takes the quickest route through the matrix), so the
gaps between consecutive tasks imply every other pair's. On the 36-task timed instance it
found and proved the optimum where successor literals with an `AddCircuit` per robot
found no schedule in 15 s (docs/schedules.md has the measurements).

Redundant, for the bound: per robot and per zone other than its start zone that it may
visit, an optional block as long as the shortest way into that zone, present when the
robot takes a task there, inside the robot's NoOverlap (it fits in the real gap before
the robot's first entry there); and per robot, shift start + work + those entries <=
makespan. Precedence, releases, deadlines, shifts, pins (robot, and start when fixed),
`not_before` and the workload cap (load bounds on each available robot) always hold.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import StrEnum

from ortools.sat.python import cp_model

from app.domain.links import Arc, ancestors_through
from app.domain.problem import Problem
from app.solvers.cpsat.common import SuccessWeights, makespan_floor
from app.solvers.cpsat.task_window import add_task_window, serial_horizon
from app.solvers.cpsat.time_scale import TimeScale


class Travel(StrEnum):
    PAIRS = "pairs"  # order literals for tasks in different zones
    NONE = "none"  # no two zones in use are apart


def zones_to_enter(problem: Problem, r: int, tasks: Sequence[int]) -> dict[int, list[int]]:
    """Per zone robot r must travel into if it takes any of `tasks` there: every zone but
    its start zone and those where it may have a fixed task (a fact: it was there)."""
    tm = problem.instance.timing
    home = tm.robot_zone[r]
    out: dict[int, list[int]] = {}
    facts = set()
    for t in tasks:
        z = tm.task_zone[t]
        if z is None or z == home:
            continue
        if t in problem.pinned_starts:
            facts.add(z)
        out.setdefault(z, []).append(t)
    return {z: ts for z, ts in out.items() if z not in facts}


class ScheduleModel:
    def __init__(
        self,
        problem: Problem,
        scale: TimeScale,
        travel: Travel,
        weights: SuccessWeights,
        pairs: set[tuple[int, int]] | None = None,
    ) -> None:
        """`pairs`, when given, are the only (task, robot) pairs the model may use."""
        self.problem, self.scale, self.travel = problem, scale, travel
        # Strong disjunctive propagation helps the travel model's bound (36 tasks); without
        # travel it made single-worker search far worse (Mk06: 162 for 66 in the same time).
        self.travel_pairs = travel is Travel.PAIRS
        self._pairs = pairs
        tm = problem.instance.timing
        self.tm = tm
        self.model = cp_model.CpModel()
        self.candidates = [self._candidates(t) for t in range(tm.n_tasks)]
        self.horizon = self._horizon()
        self.start: list[cp_model.IntVar] = []
        self.end: list[cp_model.IntVar] = []
        self.present: dict[tuple[int, int], cp_model.IntVar] = {}
        self._intervals: list[list[cp_model.IntervalVar]] = [[] for _ in range(tm.n_robots)]
        self._tasks_on: list[list[int]] = [[] for _ in range(tm.n_robots)]
        # For complete hints: (robot, t, u, "t before u") and (robot, zone, visit, entry start).
        self._orders: list[tuple[int, int, int, cp_model.IntVar]] = []
        self._blocks: list[tuple[int, int, int, cp_model.IntVar, cp_model.IntVar, int]] = []
        self._ancestors = self._ancestor_masks() if travel is Travel.PAIRS else []
        self._add_tasks()
        self.makespan = self.model.new_int_var(self._makespan_floor(), self.horizon, "makespan")
        for r in range(tm.n_robots):
            if travel is Travel.PAIRS:
                self._add_pairs(r)
            # In the exact model the zone blocks are redundant (each fits in the real gap
            # before the robot's first entry into its zone) and tighten the bound.
            entries = self._add_zone_blocks(r) if travel is Travel.PAIRS else []
            self.model.add_no_overlap(self._intervals[r])
            self._add_energy(r, entries)
        self._add_precedence()
        self._add_cap()
        for e in self.end:
            self.model.add(self.makespan >= e)
        keys = list(self.present)
        self.es = cp_model.LinearExpr.weighted_sum(
            [self.present[k] for k in keys], [weights[k] for k in keys]
        )

    # -- building --------------------------------------------------------------------------

    def _candidates(self, t: int) -> list[int]:
        pin = self.problem.pinned.get(t)
        if pin is not None:
            return [pin]
        off, pairs = self.problem.unavailable, self._pairs
        return [
            r
            for r in self.tm.eligible_robots(t)
            if r not in off and (pairs is None or (t, r) in pairs)
        ]

    def _horizon(self) -> int:
        """The serial horizon (task_window.serial_horizon), clipped by the latest shift end
        when every shift ends."""
        tm = self.tm
        horizon = serial_horizon(self)
        shift_ends = [b for _, b in tm.shifts]
        if all(math.isfinite(b) for b in shift_ends):
            horizon = min(horizon, max(self.scale.down(b) for b in shift_ends))
        return max(horizon, 0)

    def _add_tasks(self) -> None:
        m = self.model
        for t in range(self.tm.n_tasks):
            w = add_task_window(self, t, self._intervals, self._tasks_on)
            m.add_exactly_one(w.lits)
            m.add(w.end == w.start + cp_model.LinearExpr.weighted_sum(w.lits, w.sizes))
            self.start.append(w.start)
            self.end.append(w.end)

    def _add_precedence(self) -> None:
        for t, arcs in enumerate(self.tm.links):
            if t in self.problem.pinned_starts:
                continue  # a fact: what it waited for is the report's business
            for arc in arcs:
                add_link(self.model, self.scale, arc, t, (self.start, self.end))

    def _add_cap(self) -> None:
        cap = self.problem.cap
        for r in self.problem.available:
            load = cp_model.LinearExpr.sum([self.present[t, r] for t in self._tasks_on[r]])
            self.model.add_linear_constraint(load, cap.lower, cap.upper)

    def _ancestor_masks(self) -> list[int]:
        """Per task, a bitmask of the tasks that must end before it starts (a task with a
        pinned start is a fact and waits for nothing, so no order passes through it)."""
        tm = self.tm
        masks = [0] * tm.n_tasks
        for t in tm.order:
            if t in self.problem.pinned_starts:
                continue
            for arc in tm.links[t]:
                masks[t] |= ancestors_through(arc, masks[arc.pred])
        return masks

    def _add_energy(self, r: int, entries: list[tuple[int, cp_model.IntVar]]) -> None:
        """Redundant: a robot's work and zone entries fit between its shift start and the
        makespan (CP-SAT's default linear relaxation does not see this through NoOverlap)."""
        # Fixed tasks may lie before the shift start: only the others count.
        mine = [t for t in self._tasks_on[r] if t not in self.problem.pinned_starts]
        if not mine:
            return
        up = self.scale.up
        terms = [self.present[t, r] for t in mine] + [v for _, v in entries]
        coeffs = [up(self.tm.duration(t, r)) for t in mine] + [size for size, _ in entries]
        load = cp_model.LinearExpr.weighted_sum(terms, coeffs)
        self.model.add(self.makespan >= up(self.tm.shifts[r][0]) + load)

    def _add_pairs(self, r: int) -> None:
        tm, m, up = self.tm, self.model, self.scale.up
        mine = self._tasks_on[r]
        ancestors = self._ancestors
        for i, t in enumerate(mine):
            a = up(tm.travel_to_task(tm.robot_zone[r], t))
            if a and t not in self.problem.pinned_starts:  # a fact needs no way there
                m.add(self.start[t] >= up(tm.shifts[r][0]) + a).only_enforce_if(self.present[t, r])
            for u in mine[i + 1 :]:
                zt, zu = tm.task_zone[t], tm.task_zone[u]
                if zt == zu:
                    continue
                both = [self.present[t, r], self.present[u, r]]
                if ancestors[u] >> t & 1:
                    self._add_after(r, t, u, both)
                    continue
                if ancestors[t] >> u & 1:
                    self._add_after(r, u, t, both)
                    continue
                before = m.new_bool_var(f"b{r}_{t}_{u}")
                self._orders.append((r, t, u, before))
                self._add_after(r, t, u, [*both, before])
                self._add_after(r, u, t, [*both, before.Not()])

    def _add_after(self, r: int, t: int, u: int, when: Sequence[cp_model.LiteralT]) -> None:
        add_after(self.model, self.problem, self.scale, self.start, self.end, (r, t, u), when)

    def _add_zone_blocks(self, r: int) -> list[tuple[int, cp_model.IntVar]]:
        """Per zone other than the start zone: (minutes into it, visited literal)."""
        tm, m, up = self.tm, self.model, self.scale.up
        home = tm.robot_zone[r]
        if home is None or not tm.has_travel:
            return []  # a robot that starts at its first task has no first entry to bound
        by_zone = zones_to_enter(self.problem, r, self._tasks_on[r])
        a, b = tm.shifts[r]
        lo = up(a)
        hi = self.horizon if not math.isfinite(b) else self.scale.down(b)
        entries = []
        for z, tasks in by_zone.items():
            into = min(tm.travel_minutes[y][z] for y in range(len(tm.zones)) if y != z)
            size = up(into)
            if size <= 0:
                continue
            visit = m.new_bool_var(f"visit{r}_{z}")
            for t in tasks:
                m.add_implication(self.present[t, r], visit)
            start = m.new_int_var(lo, max(lo, hi - size), f"enter{r}_{z}")
            block = m.new_optional_fixed_size_interval_var(start, size, visit, f"travel{r}_{z}")
            self._intervals[r].append(block)
            entries.append((size, visit))
            self._blocks.append((r, z, size, visit, start, lo))
        return entries

    def _makespan_floor(self) -> int:
        """Every schedule of this model lasts at least this (pinned starts are facts)."""
        return self.scale.down(makespan_floor(self.problem, self._pairs))

    # -- hints and answers -----------------------------------------------------------------

    def hint(self, robots: Sequence[int], starts: Sequence[float]) -> None:
        """A whole plan as the solution hint, every auxiliary literal included: CP-SAT
        starts from it at once instead of completing tens of thousands of literals."""
        m, tm, units = self.model, self.tm, self.scale.units_per_minute
        m.clear_hints()
        if any((t, r) not in self.present for t, r in enumerate(robots)):
            return  # a plan this model cannot express (a pair it leaves out) hints nothing
        at = [round(s * units) for s in starts]
        ends = [at[t] + self.scale.up(tm.duration(t, robots[t])) for t in range(tm.n_tasks)]
        for t, r in enumerate(robots):
            for q in self.candidates[t]:
                m.add_hint(self.present[t, q], q == r)
            m.add_hint(self.start[t], at[t])
            m.add_hint(self.end[t], ends[t])
        for _, t, u, before in self._orders:
            m.add_hint(before, (at[t], t) < (at[u], u))
        for r, z, size, visit, start, lo in self._blocks:
            there = [at[t] for t in self._tasks_on[r] if robots[t] == r and tm.task_zone[t] == z]
            m.add_hint(visit, bool(there))
            # in the real gap before the robot's first entry into the zone
            m.add_hint(start, max(lo, min(there) - size) if there else lo)
        m.add_hint(self.makespan, max(ends, default=0))

    def read(self, solver: cp_model.CpSolver) -> tuple[list[int], list[float]]:
        robots = [
            next(r for r in self.candidates[t] if solver.boolean_value(self.present[t, r]))
            for t in range(self.tm.n_tasks)
        ]
        starts = [self.scale.minutes(solver.value(s)) for s in self.start]
        return robots, starts


def add_after(
    model: cp_model.CpModel,
    problem: Problem,
    scale: TimeScale,
    start: Sequence[cp_model.IntVar],
    end: Sequence[cp_model.LinearExprT],
    robot_pair: tuple[int, int, int],
    when: Sequence[cp_model.LiteralT],
) -> None:
    """Task u after task t on robot r (`robot_pair` = (r, t, u)), with the travel between
    them, where `when` holds. The robot travels within its shift, so after a fixed task
    that ended before the shift started, the way starts at the shift start."""
    r, t, u = robot_pair
    tm, up = problem.instance.timing, scale.up
    move = up(tm.travel(tm.task_zone[t], tm.task_zone[u]))
    fixed = problem.pinned_starts.get(t)
    if fixed is None:
        model.add(start[u] >= end[t] + move).only_enforce_if(when)
        return
    free = max(up(fixed + tm.duration(t, r)), up(tm.shifts[r][0]))
    model.add(start[u] >= free + move).only_enforce_if(when)


def add_link(
    model: cp_model.CpModel,
    scale: TimeScale,
    arc: Arc,
    t: int,
    times: tuple[Sequence[cp_model.LinearExprT], Sequence[cp_model.LinearExprT]],
) -> None:
    """Task t's link `arc` (docs/schedules.md#links) over the start and end variables
    `times`: its start (FS, SS) or end (FF, SF) at least the lag after the predecessor's end
    (FS, FF) or start (SS, SF); the lag rounded up, the safe side (`TimeScale`)."""
    start, end = times
    before = start[arc.pred] if arc.from_start else end[arc.pred]
    after = end[t] if arc.to_end else start[t]
    model.add(after >= before + scale.up(arc.lag))
