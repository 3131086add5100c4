"""A lower bound on the makespan from load alone: the LP relaxation of the assignment.

Each task split fractionally over the robots it may take; expected success held at its
target (or above its floor) and the cap kept; T above each robot's time line
(docs/schedules.md#bounds):

    T >= work + zone entries + group entries + S_r * y_r

- work: its (fractional) tasks' durations;
- zone entries: every zone it works in other than its start zone must be entered once,
  at least the shortest way into that zone from any other (v_rz >= x_tr for each task t
  of zone z, as the CP-SAT assignment model counts them);
- group entries: zones joined by the shortest way between zones form groups (a floor
  of the generated sites); the first way into a group other than the start zone's comes
  from outside it, so it costs at least the shortest way in from outside, more than
  the zone's entry by `into_g - max way_z` (u_rg >= v_rz for its zones);
- routes (with `routes`, where there is no fact): a second row per robot, T >= work +
  route + S'_r * y_r, where the route is a share over the sets of zones it may enter,
  each at the shortest way from its start zone through all of the set (w_rS; v_rz <= the
  shares of the sets through z, at most one set in all): the entries price each zone's
  first way in on its own, a route the ways between them too (a robot at A that works
  in B, C and D, of which only C and D are near each other, pays A-B and B-C, not two
  ways in from the nearest zone). S'_r is S_r but for the first task's way there: the
  route holds all of it, so G'_r takes the whole way from the start zone off that task's
  earliest start, where G_r takes off its zone's and group's entries;
- S_r, what the line holds before and after the work: the shift start (less the first
  zone's entry for a robot without a start zone: it starts there); with heads and tails
  and no fixed start, G_r + Q_r: the robot's first task cannot start before its head
  nor before the robot gets there from its start zone (less the entries of that zone
  and its group, already counted), and its last task leaves at least its tail of chain
  behind it; G_r the least of these starts, Q_r the least tail over the tasks it may
  take. y_r >= x_tr for each of its pairs (but a fixed start's: a fact holds no shift),
  y_r <= 1 (fixed at 1 where the cap makes it take a task): in a whole assignment y_r is
  1 when the robot works at all, and a robot that takes nothing holds nothing up.

Fixing ES at the optimum keeps the LP on the face of ES-optimal allocations, so it sees
what pushes the makespan up when the best robots must take the most tasks, and the
entries see that those tasks lie in many zones and floors. Solved by HiGHS through SciPy
(interior point, no presolve: measured at 1,000 x 20, 2.3 s of CPU where the dual
simplex took 6); on the 1,000-task x 20-robot generated instance it proves 3,371
minutes (3,362 without the group entries, 3,116 the plain load LP).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from scipy.optimize import linprog
from scipy.sparse import csr_matrix, vstack

from app.domain.problem import Problem
from app.solvers.cpsat.common import SuccessWeights
from app.solvers.cpsat.model import zones_to_enter
from app.solvers.cpsat.time_scale import TimeScale
from app.solvers.cpsat.zone_routes import zone_routes

# HiGHS works in floating point: the bound steps back this share of itself (and a hair
# more) so that it stays a bound.
STEP_BACK = 1e-7


class _Lp:
    """The LP's columns (pair shares, zone visits, group entries, routes, robots' y, then
    T) and rows."""

    def __init__(
        self,
        problem: Problem,
        candidates: Sequence[Sequence[int]],
        entries: bool,
        routes: bool = False,
    ) -> None:
        tm = self.tm = problem.instance.timing
        self.problem = problem
        self.pairs = [(t, r) for t, robots in enumerate(candidates) for r in robots]
        self.index = {p: i for i, p in enumerate(self.pairs)}
        # (robot, zone, minutes into it, tasks there robot may take)
        self.visits: list[tuple[int, int, float, list[int]]] = []
        self.mine: list[list[int]] = [[] for _ in range(tm.n_robots)]
        for t, r in self.pairs:
            self.mine[r].append(t)
        if entries and tm.has_travel:
            for r in range(tm.n_robots):
                for z, tasks in zones_to_enter(problem, r, self.mine[r]).items():
                    way = min(tm.travel_minutes[y][z] for y in range(len(tm.zones)) if y != z)
                    if way > 0:
                        self.visits.append((r, z, way, tasks))
        # (robot, group, minutes its first entry adds, the group's visit columns)
        self.groups: list[tuple[int, int, float, list[int]]] = []
        self.group_of: list[int] = []
        if self.visits and not problem.pinned_starts:
            self.group_of, self.groups = _group_entries(problem, self.visits)
        # (robot, the visit columns of a set of zones it may enter, its shortest route)
        self.routes: list[tuple[int, list[int], float]] = []
        if routes and self.visits and not problem.pinned_starts:
            self.routes = zone_routes(problem, self.visits)
        self.k, self.nv, self.m = len(self.pairs), len(self.visits), tm.n_robots
        self.g0 = self.k + self.nv  # first group column
        self.w0 = self.g0 + len(self.groups)  # first route column
        self.y0 = self.w0 + len(self.routes)  # first y column
        self.n_cols = self.y0 + self.m + 1

    def _group_added(self, added: dict[tuple[int, int], float], r: int, z: int | None) -> float:
        if z is None or not self.group_of:
            return 0.0
        return added.get((r, self.group_of[z]), 0.0)

    def col(self, values: np.ndarray, rows: np.ndarray, cols: np.ndarray, n: int) -> csr_matrix:
        return csr_matrix((values, (rows, cols)), shape=(n, self.n_cols))

    def line_starts(self, heads: np.ndarray | None, tails: np.ndarray | None) -> np.ndarray:
        """Per robot, what its time line adds to its work and entries if it works at all:
        its shift start (less its first zone's entry when it has no start zone: it starts
        there), or with `heads` and `tails` and no fact, G_r + Q_r."""
        tm, problem = self.tm, self.problem
        entry = {(r, z): way for r, z, way, _ in self.visits}
        starts = np.array([a for a, _ in tm.shifts], dtype=float)
        for r in range(self.m):
            if tm.robot_zone[r] is None:
                starts[r] -= max((w for (q, _), w in entry.items() if q == r), default=0.0)
        if heads is None or tails is None or problem.pinned_starts:
            return starts  # a fact puts the robot where its task was, not at its start zone
        # The first task's way there pays its group's entry too: left out of G as the
        # zone's entry is (no leg counted twice).
        added = {(r, g): w for r, g, w, _ in self.groups}
        for r, tasks in enumerate(self.mine):
            if not tasks:
                continue
            a = tm.shifts[r][0]
            first = min(
                max(heads[t], a + tm.travel_to_task(tm.robot_zone[r], t))
                - entry.get((r, tm.task_zone[t]), 0.0)  # type: ignore[arg-type]
                - self._group_added(added, r, tm.task_zone[t])
                for t in tasks
            )
            starts[r] = max(starts[r], first + min(tails[t] for t in tasks))
        return starts

    def route_starts(self, heads: np.ndarray | None, tails: np.ndarray | None) -> np.ndarray:
        """Per robot with routes, what its time line adds to its work and route if it
        works at all (0 for the others: they have no such row): its shift start, or with
        `heads` and `tails`, G'_r + Q_r: its first task cannot start before its head nor
        before the robot gets there, and that first way is part of the route, so G'_r is
        the least of those starts less the way there."""
        tm = self.tm
        starts = np.zeros(self.m)
        for r in {r for r, _, _ in self.routes}:
            tasks, a = self.mine[r], tm.shifts[r][0]
            starts[r] = a
            if heads is None or tails is None:
                continue
            ways = [tm.travel_to_task(tm.robot_zone[r], t) for t in tasks]
            first = min(max(heads[t], a + w) - w for t, w in zip(tasks, ways, strict=True))
            starts[r] = max(a, first) + min(tails[t] for t in tasks)
        return starts

    def time_rows(self, starts: np.ndarray, entry_weight: float) -> tuple[csr_matrix, np.ndarray]:
        """work + entries + group entries + start * y - T <= 0, per robot (the entries
        `entry_weight` times over)."""
        tm, k, m = self.tm, self.k, self.m
        robot_of = np.array([r for _, r in self.pairs], dtype=int)
        work = [
            0.0 if t in self.problem.pinned_starts else tm.duration(t, r) for t, r in self.pairs
        ]
        rows = [robot_of, np.array([r for r, *_ in self.visits], dtype=int)]
        cols = [np.arange(k), k + np.arange(self.nv)]
        vals = [np.array(work), entry_weight * np.array([w for _, _, w, _ in self.visits])]
        rows.append(np.array([r for r, *_ in self.groups], dtype=int))
        cols.append(self.g0 + np.arange(len(self.groups)))
        vals.append(entry_weight * np.array([w for _, _, w, _ in self.groups]))
        rows += [np.arange(m), np.arange(m)]
        cols += [self.y0 + np.arange(m), np.full(m, self.n_cols - 1)]
        vals += [starts, -np.ones(m)]
        matrix = self.col(np.concatenate(vals), np.concatenate(rows), np.concatenate(cols), m)
        return matrix, np.zeros(m)

    def route_time_rows(
        self, starts: np.ndarray, entry_weight: float
    ) -> tuple[csr_matrix, np.ndarray]:
        """work + route + start' * y - T <= 0, per robot with routes (the routes
        `entry_weight` times over)."""
        robots = sorted({r for r, _, _ in self.routes})
        row_of = {r: i for i, r in enumerate(robots)}
        rows, cols, vals = [], [], []
        for i, (t, r) in enumerate(self.pairs):
            if r in row_of:
                rows.append(row_of[r])
                cols.append(i)
                vals.append(self.tm.duration(t, r))
        for j, (r, _, minutes) in enumerate(self.routes):
            rows.append(row_of[r])
            cols.append(self.w0 + j)
            vals.append(entry_weight * minutes)
        for r, i in row_of.items():
            rows += [i, i]
            cols += [self.y0 + r, self.n_cols - 1]
            vals += [starts[r], -1.0]
        matrix = self.col(
            np.array(vals), np.array(rows, dtype=int), np.array(cols, dtype=int), len(robots)
        )
        return matrix, np.zeros(len(robots))

    def route_rows(self) -> tuple[csr_matrix, np.ndarray]:
        """v_rz - (the routes through z) <= 0 for each zone z robot r may enter, and at
        most one route per robot (its routes' shares sum to at most 1)."""
        rows, cols, vals = [], [], []
        through: dict[int, list[int]] = {}
        for j, (_, visits, _) in enumerate(self.routes):
            for v in visits:
                through.setdefault(v, []).append(j)
        i = 0
        for v, routes in through.items():
            rows += [i] * (1 + len(routes))
            cols += [self.k + v, *(self.w0 + j for j in routes)]
            vals += [1.0, *([-1.0] * len(routes))]
            i += 1
        robots = sorted({r for r, _, _ in self.routes})
        for r in robots:
            mine = [j for j, (q, _, _) in enumerate(self.routes) if q == r]
            rows += [i] * len(mine)
            cols += [self.w0 + j for j in mine]
            vals += [1.0] * len(mine)
            i += 1
        rhs = np.r_[np.zeros(len(through)), np.ones(len(robots))]
        matrix = self.col(np.array(vals), np.array(rows, dtype=int), np.array(cols, dtype=int), i)
        return matrix, rhs

    def visit_rows(self) -> csr_matrix:
        """x_tr - v_rz <= 0 for every task t robot r may take in a zone z it must enter."""
        rows, cols, vals = [], [], []
        i = 0
        for j, (r, _, _, tasks) in enumerate(self.visits):
            for t in tasks:
                rows += [i, i]
                cols += [self.index[t, r], self.k + j]
                vals += [1.0, -1.0]
                i += 1
        return self.col(np.array(vals), np.array(rows, dtype=int), np.array(cols, dtype=int), i)

    def group_rows(self) -> csr_matrix:
        """v_rz - u_rg <= 0 for every zone z of a group g robot r enters from outside."""
        rows, cols, vals = [], [], []
        i = 0
        for j, (*_, visits) in enumerate(self.groups):
            for v in visits:
                rows += [i, i]
                cols += [self.k + v, self.g0 + j]
                vals += [1.0, -1.0]
                i += 1
        return self.col(np.array(vals), np.array(rows, dtype=int), np.array(cols, dtype=int), i)

    def loads(self) -> csr_matrix:
        robot_of = np.array([r for _, r in self.pairs], dtype=int)
        return self.col(np.ones(self.k), robot_of, np.arange(self.k), self.m)

    def y_rows(self, starts: np.ndarray, fixed: set[int]) -> csr_matrix:
        """x_tr - y_r <= 0 for every pair (but a fact's) of a robot whose y counts and is
        not fixed at 1: y_r is 1 once it works (a fact alone does not hold its shift)."""
        facts = self.problem.pinned_starts
        keep = [
            i
            for i, (t, r) in enumerate(self.pairs)
            if starts[r] > 0 and r not in fixed and t not in facts
        ]
        rows = np.repeat(np.arange(len(keep)), 2)
        cols = np.array([[i, self.y0 + self.pairs[i][1]] for i in keep], dtype=int).reshape(-1)
        vals = np.tile([1.0, -1.0], len(keep))
        return self.col(vals, rows, cols, len(keep))


class Relaxation(NamedTuple):
    """The LP's optimum in minutes (0.0 when HiGHS did not finish) and each task's shares
    over the robots (tasks x robots; None when it did not finish)."""

    minutes: float
    shares: np.ndarray | None


def load_relaxation(
    problem: Problem,
    candidates: Sequence[Sequence[int]],
    weights: SuccessWeights,
    *,
    es_target: int | None,
    es_floor: int | None,
    time_limit_s: float,
    heads: np.ndarray | None = None,
    tails: np.ndarray | None = None,
    scale: TimeScale | None = None,
    entry_weight: float = 1.0,
    routes: bool = False,
) -> Relaxation:
    """The LP's optimum, a lower bound in minutes (0.0 when HiGHS does not finish within
    `time_limit_s`), and its shares. `heads` and `tails` (`bounds.chains`) add the zone
    entries and each robot's first start and last tail (without them: the plain load LP, a
    fifth of the time); with an exact `scale` the bound is rounded up to its unit (every
    time of an earliest-start schedule is a whole number of units). `entry_weight` prices
    every zone and group entry that many times over: above 1 the optimum is no bound, but
    its shares are an assignment that keeps each robot in fewer zones
    (`large._lp_rounded`, the planner's use: a robot enters a zone more than once when its
    work there is spread in time)."""
    lp = _Lp(problem, candidates, heads is not None and tails is not None, routes)
    n, k, m = problem.instance.n_tasks, lp.k, lp.m
    task_of = np.array([t for t, _ in lp.pairs], dtype=int)
    full = heads is not None and tails is not None
    starts = lp.line_starts(heads, tails)
    time_rows, time_rhs = lp.time_rows(starts, entry_weight)
    route_starts = lp.route_starts(heads, tails)
    route_time, route_time_rhs = lp.route_time_rows(route_starts, entry_weight)
    route_rows, route_rhs = lp.route_rows()
    loads = lp.loads()
    available = list(problem.available)
    cap = problem.cap
    # The cap's lower load makes every available robot work (y = 1); not so with a fact,
    # which counts in the load but holds no shift.
    fixed = set(available) if cap.lower >= 1 and not problem.pinned_starts else set()
    visit_rows, group_rows = lp.visit_rows(), lp.group_rows()
    y_rows = lp.y_rows(np.maximum(starts, route_starts), fixed)
    upper_rows = [loads[available], time_rows, visit_rows, y_rows, group_rows]
    upper_rows += [route_time, route_rows]
    upper_rhs = [
        np.full(len(available), cap.upper),
        time_rhs,
        np.zeros(visit_rows.shape[0]),
        np.zeros(y_rows.shape[0]),
        np.zeros(group_rows.shape[0]),
        route_time_rhs,
        route_rhs,
    ]
    lower_rows, lower_rhs = [loads[available]], [np.full(len(available), cap.lower)]
    es_row = lp.col(
        np.array([weights[p] for p in lp.pairs], dtype=float), np.zeros(k, int), np.arange(k), 1
    )
    eq_rows = [lp.col(np.ones(k), task_of, np.arange(k), n)]
    eq_rhs = [np.ones(n)]
    if es_target is not None:
        eq_rows.append(es_row)
        eq_rhs.append(np.array([es_target]))
    elif es_floor is not None:
        lower_rows.append(es_row)
        lower_rhs.append(np.array([es_floor]))
    cost = np.zeros(lp.n_cols)
    cost[-1] = 1.0
    result = linprog(
        cost,
        A_ub=vstack([*upper_rows, *(-row for row in lower_rows)]),
        b_ub=np.concatenate([*upper_rhs, *(-rhs for rhs in lower_rhs)]),
        A_eq=vstack(eq_rows),
        b_eq=np.concatenate(eq_rhs),
        bounds=[(0, 1)] * lp.y0 + [(1 if r in fixed else 0, 1) for r in range(m)] + [(0, None)],
        # The full LP: interior point without presolve (2.3 s of CPU at 1,000 x 20 where
        # the dual simplex took 6); the plain one: HiGHS's default (0.24 s there).
        method="highs-ipm" if full else "highs",
        options={"time_limit": max(0.1, time_limit_s), "presolve": not full},
    )
    if result.status != 0:
        return Relaxation(0.0, None)
    bound = max(0.0, float(result.fun) * (1 - STEP_BACK) - 1e-6)
    if scale is not None and scale.exact:
        units = scale.units_per_minute
        bound = math.ceil(bound * units - 1e-6) / units
    shares = np.zeros((n, m))
    np.add.at(shares, (task_of, np.array([r for _, r in lp.pairs], dtype=int)), result.x[:k])
    return Relaxation(bound, shares)


def _group_entries(
    problem: Problem, visits: Sequence[tuple[int, int, float, list[int]]]
) -> tuple[list[int], list[tuple[int, int, float, list[int]]]]:
    """Per robot and group of zones it may enter (zones joined by the shortest way
    between zones: the floors of the generated sites), the minutes the group's first
    entry adds to that zone's entry (docs/schedules.md#bounds) and its visit columns."""
    tm = problem.instance.timing
    ways = [w for row in tm.travel_minutes for w in row if w > 0]
    if not ways:
        return [], []
    group = _components(tm.travel_minutes, min(ways))
    zones = range(len(tm.zones))
    into = {
        g: min(
            (
                tm.travel_minutes[y][z]
                for z in zones
                if group[z] == g
                for y in zones
                if group[y] != g
            ),
            default=0.0,
        )
        for g in set(group)
    }
    out = []
    by_robot_group: dict[tuple[int, int], list[int]] = {}
    for j, (r, z, _, _) in enumerate(visits):
        home = tm.robot_zone[r]
        if home is None or group[home] == group[z]:
            continue
        by_robot_group.setdefault((r, group[z]), []).append(j)
    for (r, g), columns in by_robot_group.items():
        added = into[g] - max(visits[j][2] for j in columns)
        if added > 0:
            out.append((r, g, added, columns))
    return group, out


def _components(travel: Sequence[Sequence[float]], within: float) -> list[int]:
    """Each zone's group: zones joined by a way of at most `within` minutes, transitively."""
    n = len(travel)
    group = list(range(n))

    def find(z: int) -> int:
        while group[z] != z:
            group[z] = group[group[z]]
            z = group[z]
        return z

    for a in range(n):
        for b in range(a + 1, n):
            if travel[a][b] <= within or travel[b][a] <= within:
                group[find(a)] = find(b)
    return [find(z) for z in range(n)]
