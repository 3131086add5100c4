"""The order in which the LTAA graph decides a timed instance's tasks, and what each
choice would mean in time (docs/schedules.md#runs-in-time).

The graph decides one task at a time. On a timed instance the next task is, among the
tasks whose predecessors are all placed, the one that could start earliest on any robot
that may take it (ties: queue order), given the robots' timelines as decided so far;
the chosen robot appends it to its timeline (or, a task with a lead, puts it in idle time
its robot left behind: list_schedule.Timeline) at the earliest time its links allow
(docs/schedules.md#links), the robot is free and has travelled there, and its release and
`not_before` allow. It is the list scheduler's rule (app.domain.scheduling.list_schedule) with the
robot chosen at each step instead of given up front, so the graph's times are the list
schedule of its own assignment placed in its own order.

A guided run (a problem with `decide_by`, the guidance plan's starts) decides instead in
the plan's order: among the ready tasks, the one the plan starts first (ties: queue
order). Each robot that follows the plan then gets the plan's tasks in the plan's
sequence, and placed at the earliest they end no later than in the plan
(app.solvers.timed_guidance says why the order matters).

A team task (docs/allocation.md#teams) takes the list scheduler's meaning too: its members
travel to the task's zone, it starts when the last of them can begin (and its links allow)
and it occupies every member's timeline until it ends for all of them together.

Pinned tasks (a revision) are not the graph's to decide: a pin with a start is fixed on
its robot from the outset; a pin without one is placed on its robot when it comes up in
the order, like any task. Everything here is a deterministic function of the problem and
the robots chosen so far, so a resumed run rebuilds it from its stored decisions
(`replay`) and continues exactly where it stopped.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from app.domain.problem import Problem
from app.domain.scheduling.list_schedule import Timeline, team_start
from app.domain.scheduling.schedule import EPS
from app.domain.time_model import TimeModel

# A team in unit order, as app.domain.decision.Members (not imported: decision reads
# TimeOption from here).
Members = tuple[int, ...]


@dataclass(frozen=True)
class TimeOption:
    """What giving the current task to one robot would mean in time."""

    robot: int
    free: float  # when the robot is next free (its shift start while it has no task)
    travel: float  # minutes from where it is to the task's zone
    start: float
    end: float
    slack: float  # deadline - end; math.inf without a deadline
    allowed: bool  # meets the deadline and the shift (and the robot may take the task)
    why_not: str = ""  # what it breaks, when not allowed


@dataclass(frozen=True)
class Placement:
    """Where a placed task sits: its robot's timeline, and its position in the order."""

    robot: int
    start: float
    end: float
    travel: float
    seq: int  # the graph's decisions before it (pins are not counted)
    team: Members = ()  # a team task's members in unit order (robot is the first); else empty


class TimedProgress:
    """The robots' timelines and the decision order of one timed problem, step by step."""

    def __init__(self, problem: Problem) -> None:
        self.problem = problem
        tm = problem.instance.timing
        self.tm: TimeModel = tm
        n = tm.n_tasks
        self.placed: dict[int, Placement] = {}
        self.decided = 0  # free tasks placed (the graph's decisions)
        self._starts = [0.0] * n
        self._ends = [0.0] * n
        self._lines = [Timeline(a, tm.robot_zone[r]) for r, (a, _) in enumerate(tm.shifts)]
        for t, start in sorted(problem.pinned_starts.items(), key=lambda item: item[1]):
            r = problem.pinned[t]
            end = start + tm.duration(t, r)
            team = tuple(problem.pinned_teams.get(t, ()))
            for m in team or (r,):  # a pinned team holds every member's lane
                self._lines[m].fixed.append((start, end, t))
            self._starts[t], self._ends[t] = start, end
            self.placed[t] = Placement(r, start, end, 0.0, -1, team)
        self._waiting = [
            sum(1 for p in tm.predecessors[t] if p not in self.placed) for t in range(n)
        ]
        self._heap: list[tuple[float, int]] = []
        for t in range(n):
            if t not in self.placed and self._waiting[t] == 0:
                self._push(t)

    # -- the order --------------------------------------------------------------------------

    def _candidates(self, task: int) -> Iterable[int]:
        pinned = self.problem.pinned.get(task)
        if pinned is not None:
            return (pinned,)
        return (r for r in self.problem.available if self.tm.durations[task][r] is not None)

    def ready_time(self, task: int, robot: int) -> float:
        """When the task's links, release and `not_before` let `robot` start it."""
        tm = self.tm
        ready = tm.ready(task, tm.duration(task, robot), self._starts, self._ends)
        return max(ready, tm.release[task], self.problem.not_before)

    def _estimate(self, task: int) -> float:
        team = self.problem.pinned_teams.get(task)
        if team and task in self.problem.pinned:
            return self.team_start(task, tuple(team))
        return min(
            (
                self._lines[r].earliest(self.tm, task, r, self.ready_time(task, r))
                for r in self._candidates(task)
            ),
            default=math.inf,
        )

    def _key(self, task: int) -> float:
        plan = self.problem.decide_by
        if plan:
            # A fixed key: the lazy heap below never needs to refresh it.
            return plan.get(task, math.inf)
        return self._estimate(task)

    def _push(self, task: int) -> None:
        heapq.heappush(self._heap, (self._key(task), task))

    def _peek(self) -> int | None:
        """The next task in the order (estimates only grow: a lazy heap, as list_schedule)."""
        while self._heap:
            est, t = self._heap[0]
            now = self._key(t)
            if now > est + EPS:
                heapq.heapreplace(self._heap, (now, t))
                continue
            return t
        return None

    def current(self) -> int:
        """The next task the graph decides (placing pins that come up first); n_tasks when
        every task is placed."""
        while True:
            t = self._peek()
            if t is None:
                return self.tm.n_tasks
            pinned = self.problem.pinned.get(t)
            if pinned is None:
                return t
            self._place(t, pinned, tuple(self.problem.pinned_teams.get(t, ())))

    def later(self, task: int) -> tuple[int, ...] | None:
        """On an instance with team tasks, the free tasks still to decide after `task` (the
        completion check's, docs/allocation.md#teams); None without teams, whose timed runs
        keep no completion check."""
        if not self.problem.instance.has_teams:
            return None
        return tuple(t for t in self.problem.free_tasks if t != task and t not in self.placed)

    # -- a choice ---------------------------------------------------------------------------

    def options(self, task: int) -> tuple[TimeOption, ...]:
        """Per robot of the fleet: when it would start and end the task, and whether that
        meets the task's deadline and the robot's shift."""
        tm = self.tm
        deadline = tm.deadline[task]
        allowed_robots = set(self._candidates(task))
        out = []
        for r, line in enumerate(self._lines):
            duration = tm.durations[task][r]
            if duration is None or r not in allowed_robots:
                why = "cannot take the task" if duration is None else "is unavailable"
                travel = tm.travel_to_task(line.zone, task)
                out.append(
                    TimeOption(r, line.free, travel, math.inf, math.inf, -math.inf, False, why)
                )
                continue
            start = line.earliest(tm, task, r, self.ready_time(task, r))
            free, zone = line.before(start)  # idle time behind, for a lead
            travel = tm.travel_to_task(zone, task)
            end = start + duration
            slack = deadline - end
            why = ""
            if end > deadline + EPS:
                why = f"misses the deadline (minute {deadline:g}) by {end - deadline:g} min"
            elif end > tm.shifts[r][1] + EPS:
                why = f"ends after its shift (minute {tm.shifts[r][1]:g})"
            out.append(TimeOption(r, free, travel, start, end, slack, not why, why))
        return tuple(out)

    def team_start(self, task: int, members: Members) -> float:
        """When a team could start the task: the last member's arrival, raised until every
        member's timeline and the task's links agree (list_schedule.team_start)."""
        return team_start(self._lines, self.tm, task, members, self.ready_time(task, members[0]))

    def team_option(self, task: int, members: Members) -> TimeOption:
        """What giving the task to a team would mean in time: the team's start and end, and
        whether they meet the task's deadline and every member's shift ("members free in
        time", docs/allocation.md#teams). `robot`, `free` and `travel` are the member who
        arrives last (the one the start waits for)."""
        tm = self.tm
        deadline = tm.deadline[task]
        start = self.team_start(task, members)
        end = start + tm.duration(task, members[0])
        arrivals = {
            m: self._lines[m].earliest(tm, task, m, self.ready_time(task, m)) for m in members
        }
        last = max(members, key=lambda m: (arrivals[m], -m))
        line = self._lines[last]
        why = ""
        if end > deadline + EPS:
            why = f"misses the deadline (minute {deadline:g}) by {end - deadline:g} min"
        else:
            late = [m for m in members if end > tm.shifts[m][1] + EPS]
            if late:
                name = self.problem.instance.robots[late[0]].name
                why = f"ends after {name}'s shift (minute {tm.shifts[late[0]][1]:g})"
        free, zone = line.before(start)
        travel = tm.travel_to_task(zone, task)
        return TimeOption(last, free, travel, start, end, deadline - end, not why, why)

    def place(self, task: int, robot: int, team: Members = ()) -> Placement:
        """Give the current task to `robot` (a team task: to the members `team`, `robot` the
        first); idempotent: a placed task keeps its place."""
        if task in self.placed:
            return self.placed[task]
        expected = self.current()
        if task != expected:
            raise ValueError(f"task {task} is not the next in the order ({expected} is)")
        return self._place(task, robot, team)

    def _place(self, task: int, robot: int, team: Members = ()) -> Placement:
        tm = self.tm
        line = self._lines[robot]
        if team:
            start = self.team_start(task, team)
        else:
            start = line.earliest(tm, task, robot, self.ready_time(task, robot))
        travel = tm.travel_to_task(line.before(start)[1], task)
        for m in team or (robot,):
            self._lines[m].place(tm, task, m, start)
        end = start + tm.duration(task, robot)
        free = task not in self.problem.pinned
        placement = Placement(robot, start, end, travel, self.decided if free else -1, team)
        heapq.heappop(self._heap)  # `task` is the heap's top: current() said so
        self.placed[task] = placement
        self._starts[task], self._ends[task] = start, end
        if free:
            self.decided += 1
        for s in tm.successors[task]:
            self._waiting[s] -= 1
            if self._waiting[s] == 0 and s not in self.placed:
                self._push(s)
        return placement

    # -- rebuilding ---------------------------------------------------------------------------

    @classmethod
    def replay(
        cls,
        problem: Problem,
        robots: Mapping[int, int],
        *,
        until: int | None = None,
        teams: Mapping[int, Members] | None = None,
    ) -> TimedProgress:
        """The progress after the stored decisions (task -> robot; a team task's members in
        `teams`), placed in the order; stopping at `until` (the task a resumed graph is about
        to decide again) or at the first task without a decision."""
        progress = cls(problem)
        teams = teams or {}
        while True:
            t = progress.current()
            if t >= progress.tm.n_tasks or t == until or t not in robots:
                return progress
            progress._place(t, robots[t], tuple(teams.get(t, ())))


def decision_order(
    problem: Problem, robots: Mapping[int, int], teams: Mapping[int, Members] | None = None
) -> list[int]:
    """The free tasks with a decision, in the order the graph decided them."""
    progress = TimedProgress.replay(problem, robots, teams=teams)
    placed = [(p.seq, t) for t, p in progress.placed.items() if p.seq >= 0]
    return [t for _, t in sorted(placed)]
