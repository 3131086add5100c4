"""One neighbourhood of the large-instance LNS: the exact model around a current schedule.

The free tasks may change robot (among their allowed pairs) and position; every other task
keeps its robot and its place in its robot's order, but its times float: an improvement
in the window shifts everything after it. So per robot the fixed tasks form a chain
(each starts after the previous one's end plus the travel between them), and a free task
on that robot goes after the last fixed task that ended before the window and before
the first that started after it, with an order literal against each fixed task inside
the window and each other free task it may share the robot with (tasks in the same zone
need none: the robot's NoOverlap separates them). This is exact for what it leaves free
because travel obeys the triangle inequality: a task inserted between two chained tasks
only lengthens their gap. Precedence, releases, deadlines, shifts, pins, `not_before`,
the cap (fixed loads plus the free tasks' presences) and the ES condition (the free tasks'
share, given the fixed tasks') hold as in the exact model (`model.py`).

With `tail_minutes` (where the speeds decide the robots), only the tasks that start
within that many minutes after the window float; later ones keep their times, as
constants the floating ones must still meet (each robot's order, precedence). A smaller
model is built faster, and the answer is re-timed at earliest times in any case
(docs/schedules.md#anytime). `compact` (there too) builds the same neighbourhood
smaller: two free tasks get one order literal and one that they share a robot, whichever
robot it is (the way between them is the same for every robot), where each robot had
its own; and with `robots` (an exchange among a few robots) the other robots' tasks that
no floating task of those robots comes before, through a link or a robot's order, keep
their times: nothing in the neighbourhood can delay them.

Objective: the makespan, then the sum of the free tasks' ends (weighted below one minute
of makespan): a window off the critical path still gets compacted, which later windows
build on.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from itertools import pairwise

from ortools.sat.python import cp_model

from app.domain.scheduling.schedule import Schedule
from app.solvers.cpsat.model import add_after, add_link
from app.solvers.cpsat.outcome import Setup


class Neighbourhood:
    def __init__(
        self,
        setup: Setup,
        current: Schedule,
        free: Collection[int],
        candidates: Sequence[Sequence[int]],
        ancestors: Sequence[int],
        float_tail: bool = False,
        tail_minutes: float | None = None,
        robots: Collection[int] | None = None,
        compact: bool = False,
    ) -> None:
        problem, scale = setup.problem, setup.scale
        self.problem, self.scale, self.setup = problem, scale, setup
        tm = self.tm = problem.instance.timing
        self.free = sorted(free)
        self.robots = current.assignment
        self._ancestors = ancestors
        units = scale.units_per_minute
        self._at = [round(s.start * units) for s in current.slots]
        m = self.model = cp_model.CpModel()
        slack = 0 if scale.exact else tm.n_tasks  # rounding up may lengthen a non-whole plan
        self.horizon = scale.up(current.makespan) + slack
        self.start: list[cp_model.IntVar] = []
        self.end: list[cp_model.IntVar] = []
        self.present: dict[tuple[int, int], cp_model.IntVar] = {}
        self._orders: list[tuple[int, int, cp_model.IntVar]] = []
        self._same: dict[tuple[int, int], cp_model.IntVar] = {}
        is_free = set(self.free)
        self._candidates = {f: list(candidates[f]) for f in self.free}
        lo = min(current.slots[f].start for f in self.free)
        hi = max(current.slots[f].end for f in self.free)
        # Tasks that end before the window depend on nothing in it: the current schedule
        # has them at their earliest times, and every free task goes after them.
        self.frozen = {
            s.task
            for s in current.slots
            if s.task not in is_free and (s.end <= lo or not float_tail)
        }
        # Kept in time besides the tasks before the window: those past the floating tail,
        # and, in an exchange among a few robots, the others' tasks nothing that floats
        # can push.
        self.later: set[int] = set()
        if float_tail and tail_minutes is not None:
            self.later = {
                s.task
                for s in current.slots
                if s.task not in is_free and s.start >= hi + tail_minutes
            }
            self.frozen |= self.later
        self._compact = compact
        sequences = current.sequences(tm.n_robots)
        if compact and float_tail and robots is not None:
            unpushed = self._unpushed(current, sequences, robots)
            self.later |= unpushed
            self.frozen |= unpushed
        self._add_times()
        for r in range(tm.n_robots):
            chain = [t for t in sequences[r] if t not in is_free]
            before = [t for t in chain if current.slots[t].end <= lo]
            after = [t for t in chain if current.slots[t].start >= hi]
            inside = chain[len(before) : len(chain) - len(after)]
            self._add_chain(r, chain)
            self._add_free_on(r, before, inside, after)
        self._add_precedence()
        self._add_cap()
        self._add_success()
        kept_end = max(
            (self._at[t] + scale.up(tm.duration(t, self.robots[t])) for t in self.later), default=0
        )
        self.makespan = m.new_int_var(kept_end, self.horizon, "makespan")
        for t, e in enumerate(self.end):
            if t not in self.frozen:
                m.add(self.makespan >= e)
        weight = len(self.free) * (self.horizon + 1) + 1
        m.minimize(self.makespan * weight + sum(self.end[f] for f in self.free))
        self._hint()

    def _unpushed(
        self, current: Schedule, sequences: list[list[int]], robots: Collection[int]
    ) -> set[int]:
        """The floating tasks of robots outside `robots` that no floating task of `robots`
        comes before, through a link or a robot's order, directly or not: nothing that
        moves can delay them, so they keep their times."""
        tm, slots = self.tm, current.slots
        nexts: list[list[int]] = [[u for u, _ in links] for links in tm.successor_links]
        for chain in sequences:
            for t, u in pairwise(chain):
                nexts[t].append(u)
        floating = [t for t in range(tm.n_tasks) if t not in self.frozen]
        reached = {t for t in floating if slots[t].robot in robots}
        stack = list(reached)
        while stack:
            for u in nexts[stack.pop()]:
                if u not in reached and u not in self.frozen:
                    reached.add(u)
                    stack.append(u)
        return {t for t in floating if t not in reached}

    def _add_times(self) -> None:
        tm, m, up, down = self.tm, self.model, self.scale.up, self.scale.down
        units = self.scale.units_per_minute
        for t in range(tm.n_tasks):
            if t in self.frozen:
                at = self._at[t]
                self.start.append(m.new_constant(at))
                self.end.append(m.new_constant(at + up(tm.duration(t, self.robots[t]))))
                continue
            fixed = self.problem.pinned_starts.get(t)
            if fixed is not None:
                lo = hi = round(fixed * units)
                end_hi = max(self.horizon, hi + max(up(tm.duration(t, r)) for r in self._on(t)))
            else:
                lo = max(up(tm.release[t]), up(self.problem.not_before))
                hi = self.horizon
                end_hi = hi if not math.isfinite(tm.deadline[t]) else min(hi, down(tm.deadline[t]))
            start = m.new_int_var(lo, max(lo, hi), f"s{t}")
            end = m.new_int_var(lo, max(lo, end_hi), f"e{t}")
            self.start.append(start)
            self.end.append(end)
            if t not in self._candidates:
                r = self.robots[t]
                m.add(end == start + up(tm.duration(t, r)))
                continue
            lits, sizes = [], []
            for r in self._candidates[t]:
                lit = m.new_bool_var(f"x{t}_{r}")
                self.present[t, r] = lit
                lits.append(lit)
                sizes.append(up(tm.duration(t, r)))
                a, b = tm.shifts[r]
                if fixed is None and up(a) > lo:  # a pinned start is a fact: no shift on it
                    m.add(start >= up(a)).only_enforce_if(lit)
                if fixed is None and math.isfinite(b):
                    m.add(end <= down(b)).only_enforce_if(lit)
            m.add_exactly_one(lits)
            m.add(end == start + cp_model.LinearExpr.weighted_sum(lits, sizes))

    def _on(self, t: int) -> list[int]:
        return self._candidates.get(t, [self.robots[t]])

    def _add_chain(self, r: int, chain: list[int]) -> None:
        """The fixed tasks of robot r keep their order: each after the previous one, the
        first after the shift start and the way from the start zone."""
        tm, m, up = self.tm, self.model, self.scale.up
        a, b = tm.shifts[r]
        for t in chain:
            if t in self.problem.pinned_starts or t in self.frozen:
                continue  # a fact: its shift and deadline are not held against the plan
            if up(a) > 0:
                m.add(self.start[t] >= up(a))
            if math.isfinite(b):
                m.add(self.end[t] <= self.scale.down(b))
        if chain and chain[0] not in self.problem.pinned_starts and chain[0] not in self.frozen:
            way = up(tm.travel_to_task(tm.robot_zone[r], chain[0]))
            m.add(self.start[chain[0]] >= up(a) + way)
        for t, u in pairwise(chain):
            # Between two tasks kept in time (before the window, past the floating tail or
            # out of reach of what floats) the current plan already holds the order.
            if t not in self.frozen or u not in self.frozen:
                self._add_after(r, t, u, [])

    def _add_free_on(self, r: int, before: list[int], inside: list[int], after: list[int]) -> None:
        tm, m, up = self.tm, self.model, self.scale.up
        mine = [f for f in self.free if r in self._candidates[f]]
        if not mine:
            return
        intervals = [
            m.new_fixed_size_interval_var(self.start[u], up(tm.duration(u, r)), f"i{u}")
            for u in inside
        ]
        for i, f in enumerate(mine):
            x = self.present[f, r]
            intervals.append(
                m.new_optional_fixed_size_interval_var(
                    self.start[f], up(tm.duration(f, r)), x, f"i{f}_{r}"
                )
            )
            if before:
                self._add_after(r, before[-1], f, [x])
            elif f not in self.problem.pinned_starts:  # a fact needs no way there
                way = up(tm.travel_to_task(tm.robot_zone[r], f))
                m.add(self.start[f] >= up(tm.shifts[r][0]) + way).only_enforce_if(x)
            if after:
                self._add_after(r, f, after[0], [x])
            for u in inside:
                self._add_pair(r, f, u, [x])
            for g in mine[i + 1 :]:
                if self._compact:
                    self._add_shared(r, f, g)
                else:
                    self._add_pair(r, f, g, [x, self.present[g, r]])
        m.add_no_overlap(intervals)

    def _add_shared(self, r: int, f: int, g: int) -> None:
        """Travel between two free tasks robot r may both do. Whichever robot takes both,
        the travel between them is the same (neither is a fact), so one literal says
        they share a robot and one their order, for every robot they may share."""
        tm, m = self.tm, self.model
        if tm.task_zone[f] == tm.task_zone[g]:
            return
        same = self._same.get((f, g))
        if same is None:
            same = self._same[f, g] = m.new_bool_var(f"same{f}_{g}")
            self._add_pair(r, f, g, [same])
        m.add_bool_or([self.present[f, r].Not(), self.present[g, r].Not(), same])

    def _add_pair(self, r: int, t: int, u: int, both: list[cp_model.IntVar]) -> None:
        """Travel between two tasks robot r may both do, in whichever order they run."""
        tm = self.tm
        if tm.task_zone[t] == tm.task_zone[u]:
            return
        if self._ancestors[u] >> t & 1:
            self._add_after(r, t, u, both)
            return
        if self._ancestors[t] >> u & 1:
            self._add_after(r, u, t, both)
            return
        before = self.model.new_bool_var(f"b{r}_{t}_{u}")
        self._orders.append((t, u, before))
        self._add_after(r, t, u, [*both, before])
        self._add_after(r, u, t, [*both, before.Not()])

    def _add_after(self, r: int, t: int, u: int, when: Sequence[cp_model.LiteralT]) -> None:
        add_after(self.model, self.problem, self.scale, self.start, self.end, (r, t, u), when)

    def _add_precedence(self) -> None:
        for t, arcs in enumerate(self.tm.links):
            if t in self.problem.pinned_starts:
                continue
            for arc in arcs:
                if t not in self.frozen or arc.pred not in self.frozen:
                    add_link(self.model, self.scale, arc, t, (self.start, self.end))

    def _add_cap(self) -> None:
        cap, m = self.problem.cap, self.model
        fixed_load = [0] * self.tm.n_robots
        is_free = set(self.free)
        for t, r in enumerate(self.robots):
            if t not in is_free:
                fixed_load[r] += 1
        for r in self.problem.available:
            lits = [self.present[f, r] for f in self.free if (f, r) in self.present]
            if lits:
                m.add_linear_constraint(
                    cp_model.LinearExpr.sum(lits) + fixed_load[r], cap.lower, cap.upper
                )

    def _add_success(self) -> None:
        """The free tasks' ES share: equal to theirs now under `success_then_makespan` (ES
        stays at its proven optimum), at least what the floor leaves under `makespan`."""
        setup, weights = self.setup, self.setup.weights
        share_now = sum(weights[f, self.robots[f]] for f in self.free)
        keys = list(self.present)
        share = cp_model.LinearExpr.weighted_sum(
            [self.present[k] for k in keys], [weights[k] for k in keys]
        )
        if setup.es_target is not None:
            self.model.add(share == share_now)
        else:
            fixed_share = weights.of(self.robots) - share_now
            floor = setup.es_floor if setup.es_floor is not None else 0
            self.model.add(share >= floor - fixed_share)

    def _hint(self) -> None:
        m, tm, up = self.model, self.tm, self.scale.up
        ends = [self._at[t] + up(tm.duration(t, self.robots[t])) for t in range(tm.n_tasks)]
        for t in range(tm.n_tasks):
            if t in self.frozen:
                continue
            m.add_hint(self.start[t], self._at[t])
            m.add_hint(self.end[t], ends[t])
        for (t, r), lit in self.present.items():
            m.add_hint(lit, self.robots[t] == r)
        for (t, u), same in self._same.items():
            m.add_hint(same, self.robots[t] == self.robots[u])
        for t, u, before in self._orders:
            m.add_hint(before, (self._at[t], t) < (self._at[u], u))
        m.add_hint(self.makespan, max(ends, default=0))

    def read(self, solver: cp_model.CpSolver) -> tuple[list[int], list[float]]:
        robots = list(self.robots)
        for f in self.free:
            robots[f] = next(
                r for r in self._candidates[f] if solver.boolean_value(self.present[f, r])
            )
        return robots, [self.scale.minutes(solver.value(s)) for s in self.start]
