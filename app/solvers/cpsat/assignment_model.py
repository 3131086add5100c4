"""The large-instance path's assignment model: who does what, with time as load only.

A relaxation of the schedule: each robot's work (its tasks' durations), plus the travel
into every zone it visits other than its start zone (the shortest way in, once), plus its
shift start if it works at all, fits below T; precedence and order are dropped. So its
proven bound on T is a valid lower bound on any schedule's makespan (with the same expected-success
condition), and its answer spreads the work, which is what the makespan needs when the
success objective pushes the best robots up to the cap. One Boolean per allowed (task,
robot) pair, the cap as load bounds, ES as a linear constraint: thousands of variables
where the full scheduling model has millions of travel literals.
"""

from __future__ import annotations

from collections.abc import Sequence

from ortools.sat.python import cp_model

from app.domain.problem import Problem
from app.solvers.cpsat.common import SuccessWeights
from app.solvers.cpsat.model import zones_to_enter
from app.solvers.cpsat.time_scale import TimeScale


class AssignmentModel:
    def __init__(
        self,
        problem: Problem,
        scale: TimeScale,
        candidates: Sequence[Sequence[int]],
        weights: SuccessWeights,
    ) -> None:
        self.problem, self.scale, self.candidates = problem, scale, candidates
        tm = problem.instance.timing
        m = self.model = cp_model.CpModel()
        up = scale.up
        self.x: dict[tuple[int, int], cp_model.IntVar] = {}
        self._visits: list[tuple[int, int, cp_model.IntVar]] = []  # (robot, zone, visit)
        self._entry_size: dict[tuple[int, int], int] = {}
        on: list[list[int]] = [[] for _ in range(tm.n_robots)]
        for t, robots in enumerate(candidates):
            lits = []
            for r in robots:
                lit = m.new_bool_var(f"x{t}_{r}")
                self.x[t, r] = lit
                lits.append(lit)
                on[r].append(t)
            m.add_exactly_one(lits)
        cap = problem.cap
        for r in problem.available:
            load = cp_model.LinearExpr.sum([self.x[t, r] for t in on[r]])
            m.add_linear_constraint(load, cap.lower, cap.upper)
        total = sum(max(up(tm.duration(t, r)) for r in candidates[t]) for t in range(tm.n_tasks))
        top = max(up(a) for a, _ in tm.shifts) + total + up(self._longest_travel()) * len(tm.zones)
        self.makespan = m.new_int_var(0, top, "T")
        for r in range(tm.n_robots):
            if not on[r]:
                continue
            # Fixed tasks may lie before the shift start: only the others count.
            free = [t for t in on[r] if t not in problem.pinned_starts]
            terms = [self.x[t, r] for t in free]
            coeffs = [up(tm.duration(t, r)) for t in free]
            for size, visit in self._entries(r, on[r]):
                terms.append(visit)
                coeffs.append(size)
            start, works = up(tm.shifts[r][0]), self._works(r, free)
            if works is not None:  # the shift start only once the robot works
                terms.append(works)
                coeffs.append(start)
                start = 0
            work = cp_model.LinearExpr.weighted_sum(terms, coeffs)
            m.add(self.makespan >= start + work)
        keys = list(self.x)
        self.es = cp_model.LinearExpr.weighted_sum(
            [self.x[k] for k in keys], [weights[k] for k in keys]
        )

    def _works(self, r: int, free: list[int]) -> cp_model.IntVar | None:
        """A literal true once robot r takes a task (a robot that takes nothing, or only a
        fact, holds nothing up); None where its shift starts at 0 or the cap makes every
        robot work."""
        problem = self.problem
        if problem.instance.timing.shifts[r][0] <= 0:
            return None
        if problem.cap.lower >= 1 and not problem.pinned_starts:
            return None
        works = self.model.new_bool_var(f"w{r}")
        for t in free:
            self.model.add_implication(self.x[t, r], works)
        return works

    def _longest_travel(self) -> float:
        tm = self.problem.instance.timing
        return max((m for row in tm.travel_minutes for m in row), default=0.0)

    def _entries(self, r: int, mine: list[int]) -> list[tuple[int, cp_model.IntVar]]:
        tm = self.problem.instance.timing
        home = tm.robot_zone[r]
        if home is None or not tm.has_travel:
            return []
        by_zone = zones_to_enter(self.problem, r, mine)
        out = []
        for z, tasks in by_zone.items():
            size = self.scale.up(
                min(tm.travel_minutes[y][z] for y in range(len(tm.zones)) if y != z)
            )
            if size <= 0:
                continue
            visit = self.model.new_bool_var(f"v{r}_{z}")
            self._entry_size[r, z] = size
            for t in tasks:
                self.model.add_implication(self.x[t, r], visit)
            out.append((size, visit))
            self._visits.append((r, z, visit))
        return out

    def hint(self, robots: Sequence[int]) -> None:
        """An assignment as the whole hint: presences, zone visits and T."""
        m, tm = self.model, self.problem.instance.timing
        m.clear_hints()
        if any((t, r) not in self.x for t, r in enumerate(robots)):
            return
        for (t, r), lit in self.x.items():
            m.add_hint(lit, robots[t] == r)
        visited = {(r, tm.task_zone[t]) for t, r in enumerate(robots)}
        for r, z, visit in self._visits:
            m.add_hint(visit, (r, z) in visited)
        m.add_hint(self.makespan, self._load(robots))

    def _load(self, robots: Sequence[int]) -> int:
        """T for an assignment: the largest shift start + work + zone entries."""
        tm, up = self.problem.instance.timing, self.scale.up
        loads = [up(a) for a, _ in tm.shifts]
        for t, r in enumerate(robots):
            if t not in self.problem.pinned_starts:
                loads[r] += up(tm.duration(t, r))
        visited = {(r, tm.task_zone[t]) for t, r in enumerate(robots)}
        for key, size in self._entry_size.items():
            if key in visited:
                loads[key[0]] += size
        return max(loads)

    def read(self, solver: cp_model.CpSolver) -> list[int]:
        return [
            next(r for r in self.candidates[t] if solver.boolean_value(self.x[t, r]))
            for t in range(len(self.candidates))
        ]
