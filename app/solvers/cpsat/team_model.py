"""The CP-SAT model of a timed problem with team tasks: multi-skill project scheduling
(docs/allocation.md#teams, docs/schedules.md#teams-in-time).

Per task a start and an end; per (task, robot that may take it) a presence literal and an
optional interval on the task's start, as in `app.solvers.cpsat.model`. A single-robot task
has exactly one present robot. A team task's interval is shared by one optional interval
per eligible robot (PyJobShop's mode with several resources): assignment literals
x[t][r][f] say robot r covers a unit of feature f, a robot covers at most one unit and is
present exactly when it covers one (sum over f of x = presence), and each feature's units
are covered (sum over r of x = count). Per robot a NoOverlap over its intervals, and
between two tasks in different zones the travel (an order literal, as the one-robot
model). Precedence, releases, deadlines, shifts, pins, `not_before` and the cap (a team
task adds one to each member's load) always hold.

Redundant, for the bound: a cumulative over every task's interval with its team size as
demand and the available robots as capacity; per feature of a team, a cumulative over the
team tasks needing it (demand: their count of it) with the robots able to cover it as
capacity; per robot, shift start + its work <= makespan.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from functools import reduce

from ortools.sat.python import cp_model

from app.domain.links import ancestors_through
from app.domain.problem import Problem
from app.domain.teams import covers, team_success
from app.solvers.cpsat.model import add_after, add_link, zones_to_enter
from app.solvers.cpsat.task_window import add_task_window, serial_horizon
from app.solvers.cpsat.time_scale import TimeScale
from app.solvers.units import UnitView


def team_model_size(problem: Problem) -> int:
    """Literals of the team model: a presence per (task, robot allowed), an assignment per
    (team task, robot, feature it covers), an order per two tasks in different zones that
    one robot may both take (an upper bound: precedence saves some)."""
    instance, tm = problem.instance, problem.instance.timing
    on: list[dict[int | None, int]] = [{} for _ in range(tm.n_robots)]
    total = 0
    for t in range(tm.n_tasks):
        pin = problem.pinned.get(t)
        robots = list(problem.pinned_teams.get(t, ())) or (
            [pin] if pin is not None else tm.eligible_robots(t)
        )
        for r in robots:
            if pin is None and r in problem.unavailable:
                continue
            total += 1 + sum(covers(instance.robots[r], f) for f in set(instance.units[t]))
            on[r][tm.task_zone[t]] = on[r].get(tm.task_zone[t], 0) + 1
    if tm.has_travel:
        for counts in on:
            n = sum(counts.values())
            total += (n * n - sum(c * c for c in counts.values())) // 2
    return total


class TeamWeights:
    """Integer expected success per (task, robot) of a single-robot task and per (task,
    robot, feature) of a team unit: the integers `optimal` compares (`UnitView`), over the
    free tasks, divided by their common divisor."""

    def __init__(self, problem: Problem) -> None:
        view = UnitView.of(problem)
        raw: dict[tuple[int, int, str | None], int] = {}
        for i, t in enumerate(view.tasks):
            units = view.units[i]
            for c, r in enumerate(view.robots):
                if not view.eligible[i, c]:
                    continue
                if not units:
                    raw[t, r, None] = int(view.single_weights[i, c])
                for f in dict.fromkeys(units):
                    if covers(problem.instance.robots[r], f):
                        raw[t, r, f] = view.unit_weight(i, f, c)
        divisor = reduce(math.gcd, raw.values(), 0) or 1
        self.table = {k: v // divisor for k, v in raw.items()}
        # mean success = sum of weights * per_unit / number of tasks
        self.per_unit = divisor / (view.scale * view.multiple)
        self.n_tasks = problem.instance.n_tasks
        inst = problem.instance
        self.pinned_success = float(
            sum(
                team_success(inst.tasks[t], inst.robots, problem.pinned_teams[t])
                if t in problem.pinned_teams
                else inst.success[t, r]
                for t, r in problem.pinned.items()
            )
        )

    def of(
        self,
        assignment: Sequence[int],
        teams: Mapping[int, tuple[int, ...]],
        units: Sequence[Sequence[str]],
    ) -> int:
        """The integer ES of the free part of a plan."""
        total = 0
        for t, r in enumerate(assignment):
            if t in teams:
                total += sum(
                    self.table.get((t, m, f), 0) for m, f in zip(teams[t], units[t], strict=True)
                )
            else:
                total += self.table.get((t, r, None), 0)
        return total


class TeamModel:
    def __init__(self, problem: Problem, scale: TimeScale, weights: TeamWeights) -> None:
        self.problem, self.scale = problem, scale
        tm = problem.instance.timing
        self.tm = tm
        self.units = problem.instance.units
        self.model = cp_model.CpModel()
        self.candidates = [self._candidates(t) for t in range(tm.n_tasks)]
        self.horizon = self._horizon()
        self.start: list[cp_model.IntVar] = []
        self.end: list[cp_model.IntVar] = []
        self.present: dict[tuple[int, int], cp_model.IntVar] = {}
        self.cover: dict[tuple[int, int, str], cp_model.IntVar] = {}
        self._intervals: list[list[cp_model.IntervalVar]] = [[] for _ in range(tm.n_robots)]
        self._tasks_on: list[list[int]] = [[] for _ in range(tm.n_robots)]
        self._orders: list[tuple[int, int, cp_model.IntVar]] = []
        self._task_intervals: list[cp_model.IntervalVar] = []
        self._ancestors = self._ancestor_masks()
        self._blocks: list[tuple[int, int, int, cp_model.IntVar, cp_model.IntVar, int]] = []
        for t in range(tm.n_tasks):
            self._add_task(t)
        self.makespan = self.model.new_int_var(0, self.horizon, "makespan")
        for e in self.end:
            self.model.add(self.makespan >= e)
        for r in range(tm.n_robots):
            entries = self._add_zone_blocks(r) if tm.has_travel else []
            self.model.add_no_overlap(self._intervals[r])
            if tm.has_travel:
                self._add_travel(r)
            self._add_energy(r, entries)
        for t, arcs in enumerate(tm.links):
            if t not in problem.pinned_starts:  # docs/schedules.md#links, one place
                for arc in arcs:
                    add_link(self.model, scale, arc, t, (self.start, self.end))
        self._add_cap()
        self._add_cumulatives()
        self.twins = self._twins()
        self._break_symmetry()
        terms, coeffs = [], []
        for (t, r, f), w in weights.table.items():
            lit = self.present.get((t, r)) if f is None else self.cover.get((t, r, f))
            if lit is not None and w:
                terms.append(lit)
                coeffs.append(w)
        self.es = cp_model.LinearExpr.weighted_sum(terms, coeffs)

    def _candidates(self, t: int) -> list[int]:
        team = self.problem.pinned_teams.get(t)
        if team is not None:  # docs/living-plans.md#pins-in-allocate: the pinned members
            return list(team)
        pin = self.problem.pinned.get(t)
        if pin is not None:
            return [pin]
        off = self.problem.unavailable
        return [r for r in self.tm.eligible_robots(t) if r not in off]

    def _horizon(self) -> int:
        return serial_horizon(self)

    def _add_task(self, t: int) -> None:
        m = self.model
        w = add_task_window(self, t, self._intervals, self._tasks_on)
        size = m.new_int_var(min(w.sizes), max(w.sizes), f"d{t}")
        if not self.units[t]:
            m.add_exactly_one(w.lits)
            m.add(size == cp_model.LinearExpr.weighted_sum(w.lits, w.sizes))
        else:
            self._add_team(t)
            m.add(size == w.sizes[0])  # a team task's duration is one number
        self.start.append(w.start)
        self.end.append(w.end)
        self._task_intervals.append(m.new_interval_var(w.start, size, w.end, f"task{t}"))

    def _add_team(self, t: int) -> None:
        """Unit coverage: each unit by one present robot able to cover its feature, a robot
        covering at most one unit of the task; every member busy over the same interval."""
        m, robots = self.model, self.problem.instance.robots
        counts = dict.fromkeys(self.units[t], 0)
        for f in self.units[t]:
            counts[f] += 1
        by_feature: dict[str, list[cp_model.IntVar]] = {f: [] for f in counts}
        pinned = dict(zip(self.problem.pinned_teams.get(t, ()), self.units[t], strict=False))
        for r in self.candidates[t]:
            mine = []
            for f in counts:
                # A pinned member covers its pinned unit, whatever its skills say now.
                if (f == pinned[r]) if pinned else covers(robots[r], f):
                    x = m.new_bool_var(f"c{t}_{r}_{f}")
                    self.cover[t, r, f] = x
                    by_feature[f].append(x)
                    mine.append(x)
            m.add(cp_model.LinearExpr.sum(mine) == self.present[t, r])
        for f, count in counts.items():
            m.add(cp_model.LinearExpr.sum(by_feature[f]) == count)

    def _add_travel(self, r: int) -> None:
        """First task: from the start zone; two tasks in different zones: an order literal."""
        tm, m, up = self.tm, self.model, self.scale.up
        mine = self._tasks_on[r]
        for i, t in enumerate(mine):
            a = up(tm.travel_to_task(tm.robot_zone[r], t))
            if a and t not in self.problem.pinned_starts:
                m.add(self.start[t] >= up(tm.shifts[r][0]) + a).only_enforce_if(self.present[t, r])
            for u in mine[i + 1 :]:
                if tm.task_zone[t] == tm.task_zone[u]:
                    continue
                both = [self.present[t, r], self.present[u, r]]
                args = (m, self.problem, self.scale, self.start, self.end)
                # Where precedence fixes the order, one constraint and no literal.
                if self._ancestors[u] >> t & 1:
                    add_after(*args, (r, t, u), both)
                    continue
                if self._ancestors[t] >> u & 1:
                    add_after(*args, (r, u, t), both)
                    continue
                before = m.new_bool_var(f"b{r}_{t}_{u}")
                self._orders.append((t, u, before))
                add_after(*args, (r, t, u), [*both, before])
                add_after(*args, (r, u, t), [*both, before.Not()])

    def _ancestor_masks(self) -> list[int]:
        """Per task, a bitmask of the tasks that must end before it starts (a task with a
        pinned start is a fact and waits for nothing)."""
        masks = [0] * self.tm.n_tasks
        for t in self.tm.order:
            if t not in self.problem.pinned_starts:
                for arc in self.tm.links[t]:
                    masks[t] |= ancestors_through(arc, masks[arc.pred])
        return masks

    def _add_energy(self, r: int, entries: list[tuple[int, cp_model.IntVar]]) -> None:
        """Redundant: a robot's work and zone entries fit between its shift start and the
        makespan."""
        mine = [t for t in self._tasks_on[r] if t not in self.problem.pinned_starts]
        if mine:
            load = cp_model.LinearExpr.weighted_sum(
                [self.present[t, r] for t in mine] + [v for _, v in entries],
                [self.scale.up(self.tm.duration(t, r)) for t in mine] + [n for n, _ in entries],
            )
            self.model.add(self.makespan >= self.scale.up(self.tm.shifts[r][0]) + load)

    def _add_zone_blocks(self, r: int) -> list[tuple[int, cp_model.IntVar]]:
        """Redundant, as in the one-robot model: per zone other than the start zone that
        the robot may work in, a block as long as the shortest way into it, present when
        it works there, inside its NoOverlap (it fits in the real gap before its first
        entry there). (minutes into the zone, visited literal) per zone."""
        tm, m, up = self.tm, self.model, self.scale.up
        if tm.robot_zone[r] is None:
            return []  # it starts at its first task: no first entry to bound
        a, b = tm.shifts[r]
        lo = up(a)
        hi = self.horizon if not math.isfinite(b) else self.scale.down(b)
        entries = []
        for z, tasks in zones_to_enter(self.problem, r, self._tasks_on[r]).items():
            size = up(min(tm.travel_minutes[y][z] for y in range(len(tm.zones)) if y != z))
            if size <= 0:
                continue
            visit = m.new_bool_var(f"visit{r}_{z}")
            for t in tasks:
                m.add_implication(self.present[t, r], visit)
            start = m.new_int_var(lo, max(lo, hi - size), f"enter{r}_{z}")
            block = m.new_optional_fixed_size_interval_var(start, size, visit, f"way{r}_{z}")
            self._intervals[r].append(block)
            self._blocks.append((r, z, size, visit, start, lo))
            entries.append((size, visit))
        return entries

    def _twins(self) -> list[list[int]]:
        """Groups of interchangeable robots: the same skills, success, shift, start zone and
        duration per task (so the same presences), none pinned, none unavailable. Swapping two
        of them robot for robot maps every plan to one of the same ES, loads and makespan."""
        problem, tm = self.problem, self.tm
        fixed = {m for t, r in problem.pinned.items() for m in problem.pinned_teams.get(t, (r,))}
        success, robots = problem.instance.success, problem.instance.robots
        groups: dict[tuple[object, ...], list[int]] = {}
        for r in problem.available:
            if r in fixed:
                continue
            key = (
                robots[r].skills,
                tuple(success[:, r].tolist()),
                tm.shifts[r],
                tm.robot_zone[r],
                tuple(
                    self.scale.up(tm.duration(t, r)) if (t, r) in self.present else -1
                    for t in range(tm.n_tasks)
                ),
            )
            groups.setdefault(key, []).append(r)
        return [g for g in groups.values() if len(g) > 1]

    def _break_symmetry(self) -> None:
        """Of two interchangeable robots r < q, r's first task (in task order) comes no later
        than q's, and q works only if r does: of each plan and its swaps one stays. Twins are
        common in MSPSP-InstLib set 2c, where this closed proofs the search alone missed:
        docs/benchmarks.md#multi-skill-project-scheduling-mspsp-instlib-set-2c."""
        for group in self.twins:
            for r, q in itertools.pairwise(group):
                mine = [t for t in range(self.tm.n_tasks) if (t, r) in self.present]
                for i, t in enumerate(mine):
                    # q on t -> r on t or on an earlier task (a team may hold both)
                    earlier = [self.present[u, r] for u in mine[: i + 1]]
                    self.model.add_bool_or([*earlier, self.present[t, q].Not()])

    def _add_cap(self) -> None:
        cap = self.problem.cap
        for r in self.problem.available:
            load = cp_model.LinearExpr.sum([self.present[t, r] for t in self._tasks_on[r]])
            self.model.add_linear_constraint(load, cap.lower, cap.upper)

    def _add_cumulatives(self) -> None:
        """Redundant: robots at work at once never exceed the fleet, per feature the robots
        able to cover it (the bound's strength on team instances)."""
        # The whole fleet as capacity: a pinned task may hold an unavailable robot.
        robots = self.problem.instance.robots
        demand = [len(u) or 1 for u in self.units]
        self.model.add_cumulative(self._task_intervals, demand, len(robots))
        features = {f for u in self.units for f in u}
        pinned_on = {
            (m, g)
            for t, team in self.problem.pinned_teams.items()
            for m, g in zip(team, self.units[t], strict=True)
        }
        for f in sorted(features):
            tasks = [t for t, u in enumerate(self.units) if f in u]
            able = sum(
                1 for r, robot in enumerate(robots) if covers(robot, f) or (r, f) in pinned_on
            )
            self.model.add_cumulative(
                [self._task_intervals[t] for t in tasks],
                [self.units[t].count(f) for t in tasks],
                able,
            )

    def branch_on_starts(self) -> None:
        """Search by serial schedule generation: the task that can start earliest first, at
        its earliest start (its robots then by CP-SAT's default search)."""
        self.model.add_decision_strategy(
            self.start, cp_model.CHOOSE_LOWEST_MIN, cp_model.SELECT_MIN_VALUE
        )

    def hint(
        self,
        assignment: Sequence[int],
        teams: Mapping[int, tuple[int, ...]],
        starts: Sequence[float],
    ) -> None:
        m, tm, units = self.model, self.tm, self.scale.units_per_minute
        m.clear_hints()
        swap = self._twin_labels(assignment, teams)
        members = [{swap[m] for m in teams.get(t) or (r,)} for t, r in enumerate(assignment)]
        if any((t, r) not in self.present for t, ms in enumerate(members) for r in ms):
            return
        at = [round(s * units) for s in starts]
        ends = [at[t] + self.scale.up(tm.duration(t, assignment[t])) for t in range(tm.n_tasks)]
        for t in range(tm.n_tasks):
            for r in self.candidates[t]:
                m.add_hint(self.present[t, r], r in members[t])
            m.add_hint(self.start[t], at[t])
            m.add_hint(self.end[t], ends[t])
        covered = {
            (t, swap[r], f)
            for t, ms in teams.items()
            for r, f in zip(ms, self.units[t], strict=True)
        }
        for key, x in self.cover.items():
            m.add_hint(x, key in covered)
        for t, u, before in self._orders:
            m.add_hint(before, (at[t], t) < (at[u], u))
        for r, z, size, visit, start, lo in self._blocks:
            there = [at[t] for t in self._tasks_on[r] if r in members[t] and tm.task_zone[t] == z]
            m.add_hint(visit, bool(there))
            m.add_hint(start, max(lo, min(there) - size) if there else lo)
        m.add_hint(self.makespan, max(ends, default=0))

    def _twin_labels(
        self, assignment: Sequence[int], teams: Mapping[int, tuple[int, ...]]
    ) -> dict[int, int]:
        """A plan's robots relabelled among twins so that it keeps `_break_symmetry`'s
        order (a hint that breaks it would be repaired, not followed): robot -> its label."""
        swap = {r: r for r in range(self.tm.n_robots)}
        first: dict[int, int] = {}
        for t, r in enumerate(assignment):
            for m in teams.get(t) or (r,):
                first.setdefault(m, t)
        for group in self.twins:
            by_first = sorted(group, key=lambda r: (first.get(r, self.tm.n_tasks), r))
            swap.update(zip(by_first, group, strict=True))
        return swap

    def read(self, solver: cp_model.CpSolver) -> tuple[list[list[int]], dict[int, tuple[int, ...]]]:
        """Per robot its tasks in the solver's time order, and each team's robot per unit."""
        starts = [solver.value(s) for s in self.start]
        sequences: list[list[int]] = [[] for _ in range(self.tm.n_robots)]
        for t in sorted(range(self.tm.n_tasks), key=lambda k: (starts[k], k)):
            for r in self.candidates[t]:
                if solver.boolean_value(self.present[t, r]):
                    sequences[r].append(t)
        teams: dict[int, tuple[int, ...]] = {}
        for t, units in enumerate(self.units):
            if not units:
                continue
            free = {
                f: [
                    r
                    for r in self.candidates[t]
                    if (t, r, f) in self.cover and solver.boolean_value(self.cover[t, r, f])
                ]
                for f in dict.fromkeys(units)
            }
            teams[t] = tuple(free[f].pop(0) for f in units)
        return sequences, teams
