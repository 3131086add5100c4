"""The shared serial list scheduler (docs/schedules.md#schedulers): any assignment -> a schedule.

Every method that decides only *who* (greedy, the exact allocation solvers, the learners,
LTAA) gets its *when* here, so all methods have a makespan on the same terms. Serial
schedule generation: among the tasks whose predecessors are placed, the one that can
start earliest (ties: queue order) goes next, appended to its robot's timeline at the
earliest time its links allow (docs/schedules.md#links), its robot is free and has travelled, its
release and `not_before` allow (a task with a lead may take idle time its robot left
behind: `Timeline`). Tasks with a pinned start are facts (reported started or
done): they sit at their times from the outset and the others are placed around them.

Nothing is hidden: with a given assignment the scheduler may end a task after its
deadline or its robot's shift (waiting cannot help an append-only timeline); the schedule
says so through `check_schedule`. `sequence_schedule` re-times fixed per-robot orders the
same way: how an exact solver's answer is compacted and how a relaxed one is repaired.
"""

from __future__ import annotations

import heapq
from collections.abc import Sequence
from dataclasses import dataclass, field

from app.domain.errors import DomainError
from app.domain.problem import Problem
from app.domain.scheduling.schedule import EPS, Schedule, build_schedule
from app.domain.teams import Teams
from app.domain.time_model import TimeModel


@dataclass
class Timeline:
    """One robot: when it is next free, where it is, and its fixed tasks still ahead.

    It also keeps the idle time it has left behind (`gaps`) and when each task it holds
    starts: a task whose links let it start before one of those tasks (a lead,
    docs/schedules.md#links) may go into that idle time, where it fits with its travel
    there and on; every other task is appended, as it always was."""

    free: float
    zone: int | None
    fixed: list[tuple[float, float, int]] = field(default_factory=list)  # (start, end, task)
    # Idle time behind `free`: (opens, the zone the robot is in, closes, the zone it goes to).
    gaps: list[tuple[float, int | None, float, int | None]] = field(default_factory=list)
    starts: dict[int, float] = field(default_factory=dict)  # the tasks placed on it

    def earliest(self, tm: TimeModel, task: int, robot: int, ready: float) -> float:
        """Earliest start >= ready: in idle time behind it when a lead allows, else
        appended after the fixed tasks it cannot fit before."""
        d = tm.duration(task, robot)
        if self._leads(tm, task, ready):
            for opens, zone, closes, after in self.gaps:
                s = max(ready, opens + tm.travel_to_task(zone, task))
                if s + d + tm.travel(tm.task_zone[task], after) <= closes + EPS:
                    return s
        free, zone = self.free, self.zone
        for start, end, other in self.fixed:
            s = max(ready, free + tm.travel_to_task(zone, task))
            if s + d + tm.travel(tm.task_zone[task], tm.task_zone[other]) <= start + EPS:
                return s
            free, zone = max(free, end), tm.task_zone[other]
        return max(ready, free + tm.travel_to_task(zone, task))

    def _leads(self, tm: TimeModel, task: int, ready: float) -> bool:
        """May the task start before a predecessor this robot already holds?"""
        if not self.gaps or ready >= self.free - EPS:
            return False
        held = [self.starts[p] for p in tm.predecessors[task] if p in self.starts]
        return bool(held) and ready < max(held) - EPS

    def before(self, start: float) -> tuple[float, int | None]:
        """When the robot is free and where it is before a task starting at `start`."""
        i = None if start >= self.free - EPS else self._gap_at(start, start)
        if i is None:
            return self.free, self.zone
        opens, zone, _, _ = self.gaps[i]
        return opens, zone

    def _gap_at(self, start: float, end: float) -> int | None:
        """The first idle time behind `free` that holds [start, end]."""
        for i, (opens, _, closes, _) in enumerate(self.gaps):
            if opens - EPS <= start and end <= closes + EPS:
                return i
        return None

    def place(self, tm: TimeModel, task: int, robot: int, start: float) -> None:
        end, zone = start + tm.duration(task, robot), tm.task_zone[task]
        self.starts[task] = start
        if start < self.free - EPS:  # into idle time behind: that gap splits in two
            i = self._gap_at(start, end)
            if i is None:
                raise ValueError(f"task {task} at {start:g} fits no idle time of its robot")
            opens, before, closes, after = self.gaps[i]
            self.gaps[i : i + 1] = [(opens, before, start, zone), (end, zone, closes, after)]
            return
        while self.fixed and self.fixed[0][0] < end - EPS:
            begins, ends, other = self.fixed.pop(0)
            self._idle_until(begins, tm.task_zone[other])
            self.starts[other] = begins
            self.free, self.zone = max(self.free, ends), tm.task_zone[other]
        self._idle_until(start, zone)
        self.free, self.zone = end, zone

    def _idle_until(self, start: float, zone: int | None) -> None:
        if start > self.free + EPS:
            self.gaps.append((self.free, self.zone, start, zone))


def _check_assignment(
    problem: Problem, assignment: Sequence[int], teams: Teams | None = None
) -> TimeModel:
    instance = problem.instance
    tm = instance.timing
    if len(assignment) != tm.n_tasks:
        raise ValueError(f"{len(assignment)} robots for {tm.n_tasks} tasks; one each")
    missing = [t for t, task in enumerate(instance.tasks) if task.team and t not in (teams or {})]
    if missing:
        raise ValueError(f"team task {missing[0]} has no team: its members are needed to time it")
    for t, r in _pairs(assignment, teams):
        if tm.durations[t][r] is None:
            raise DomainError(
                f"assignment.{t}",
                f"robot '{instance.robots[r].name}' cannot take task {instance.tasks[t].id!r} "
                f"({instance.tasks[t].name}): its duration map does not name that robot, so "
                "there is no schedule for this assignment",
                code="ineligible",
            )
    return tm


def _pairs(assignment: Sequence[int], teams: Teams | None) -> list[tuple[int, int]]:
    """Every (task, robot working on it): a team task once per member."""
    teams = teams or {}
    return [(t, m) for t, r in enumerate(assignment) for m in teams.get(t) or (r,)]


def team_start(
    lines: Sequence[Timeline], tm: TimeModel, t: int, members: Sequence[int], ready: float
) -> float:
    """The earliest start every member can make: a member's earliest start only grows with
    `ready`, so raising `ready` to the latest of them until they agree ends (the task
    starts when its last member can begin, docs/allocation.md#teams)."""
    while True:
        start = max(lines[m].earliest(tm, t, m, ready) for m in members)
        if start <= ready + EPS:
            return ready
        ready = start


def list_schedule(
    problem: Problem, assignment: Sequence[int], teams: Teams | None = None
) -> Schedule:
    """Earliest-start serial list schedule of an assignment (robot index per task; a team
    task's robot per unit in `teams`)."""
    tm = _check_assignment(problem, assignment, teams)
    teams = teams or {}

    def members(t: int) -> tuple[int, ...]:
        return tuple(teams.get(t) or (assignment[t],))

    n = tm.n_tasks
    starts = [0.0] * n
    ends = [0.0] * n
    done = [False] * n
    lines = [Timeline(a, tm.robot_zone[r]) for r, (a, _) in enumerate(tm.shifts)]
    for t, start in sorted(problem.pinned_starts.items(), key=lambda item: item[1]):
        end = start + tm.duration(t, assignment[t])
        for m in members(t):  # a pinned team holds every member over its times
            lines[m].fixed.append((start, end, t))
        starts[t], ends[t], done[t] = start, end, True
    waiting = [sum(1 for p in tm.predecessors[t] if not done[p]) for t in range(n)]

    def ready_time(t: int) -> float:
        ready = tm.ready(t, tm.duration(t, assignment[t]), starts, ends)
        return max(ready, tm.release[t], problem.not_before)

    def estimate(t: int) -> float:
        if t in teams:
            return team_start(lines, tm, t, teams[t], ready_time(t))
        return lines[assignment[t]].earliest(tm, t, assignment[t], ready_time(t))

    heap = [(estimate(t), t) for t in range(n) if not done[t] and waiting[t] == 0]
    heapq.heapify(heap)
    placed = sum(done)
    while heap:
        est, t = heapq.heappop(heap)
        now = estimate(t)
        if now > est + EPS:  # its robot filled up since: estimates only grow
            heapq.heappush(heap, (now, t))
            continue
        for m in members(t):
            lines[m].place(tm, t, m, now)
        starts[t], ends[t], done[t] = now, now + tm.duration(t, assignment[t]), True
        placed += 1
        for s in tm.successors[t]:
            waiting[s] -= 1
            if waiting[s] == 0 and not done[s]:
                heapq.heappush(heap, (estimate(s), s))
    if placed != n:  # only a fixed task can release a successor that was never queued
        for t in range(n):
            if not done[t]:
                raise ValueError(f"task {t} was never ready; the precedence graph is broken")
    return build_schedule(problem, list(assignment), starts, ends, teams)


def sequence_schedule(
    problem: Problem, sequences: Sequence[Sequence[int]], teams: Teams | None = None
) -> Schedule:
    """Earliest times for fixed per-robot task orders (every task once, in some robot's
    order; a team task in each of its members', `teams` saying which unit each covers).
    A task with a pinned start keeps it. ValueError if the orders contradict the
    precedence or each other (no order of placing them works)."""
    tm = problem.instance.timing
    n = tm.n_tasks
    teams = teams or {}
    assignment = [-1] * n
    holders: list[set[int]] = [set() for _ in range(n)]
    for r, seq in enumerate(sequences):
        for t in seq:
            holders[t].add(r)
            assignment[t] = r
    for t in range(n):
        if assignment[t] == -1:
            raise ValueError(f"task {t} is in no robot's sequence")
        if t in teams:
            if holders[t] != set(teams[t]):
                raise ValueError(f"team task {t} is not in exactly its members' sequences")
            assignment[t] = teams[t][0]
        elif len(holders[t]) != 1:
            raise ValueError(f"task {t} is in {len(holders[t])} robots' sequences")
    _check_assignment(problem, assignment, teams)
    starts = [0.0] * n
    ends = [0.0] * n
    done = [False] * n
    cursor = [0] * len(sequences)
    free = [a for a, _ in tm.shifts]
    zone = list(tm.robot_zone)

    def at_front(t: int) -> bool:
        return all(
            cursor[m] < len(sequences[m]) and sequences[m][cursor[m]] == t for m in holders[t]
        )

    progress = True
    while progress:
        progress = False
        for r, seq in enumerate(sequences):
            while cursor[r] < len(seq):
                t = seq[cursor[r]]
                fixed = problem.pinned_starts.get(t)  # a fact: it waits for nothing
                if fixed is None and not all(done[p] for p in tm.predecessors[t]):
                    break
                if not at_front(t):
                    break  # a member is still busy with earlier tasks
                members = sorted(holders[t])
                if fixed is None:
                    ready = tm.ready(t, tm.duration(t, assignment[t]), starts, ends)
                    ready = max(ready, tm.release[t], problem.not_before)
                    start = max(
                        [ready] + [free[m] + tm.travel_to_task(zone[m], t) for m in members]
                    )
                else:
                    start = fixed
                starts[t], ends[t], done[t] = start, start + tm.duration(t, assignment[t]), True
                for m in members:
                    free[m], zone[m] = max(free[m], ends[t]), tm.task_zone[t]
                    cursor[m] += 1
                progress = True
    if not all(done):
        if not tm.typed or teams:
            raise ValueError("the robot orders contradict the precedence: no task can go next")
        # A lead (a negative lag) lets a robot do a successor before its predecessor, which
        # placing in order cannot: the least times that keep every rule instead.
        starts, ends = _least_times(problem, sequences, assignment)
    return build_schedule(problem, assignment, starts, ends, teams)


def _least_times(
    problem: Problem, sequences: Sequence[Sequence[int]], assignment: Sequence[int]
) -> tuple[list[float], list[float]]:
    """The earliest times of fixed per-robot orders when links run against an order
    (docs/schedules.md#links): every rule but the deadlines and shift ends is a lower bound
    on a start, so raising each start to what the others ask until nothing moves reaches
    the least times (Bellman-Ford over the orders); still moving after n + 1 rounds means
    a cycle no times can keep (ValueError)."""
    tm = problem.instance.timing
    n = tm.n_tasks
    starts = [0.0] * n
    ends = [0.0] * n
    for _ in range(n + 1):
        moved = False
        for r, seq in enumerate(sequences):
            free, zone = tm.shifts[r][0], tm.robot_zone[r]
            for t in seq:
                fixed = problem.pinned_starts.get(t)
                d = tm.duration(t, r)
                if fixed is None:
                    ready = tm.ready(t, d, starts, ends)
                    ready = max(ready, tm.release[t], problem.not_before)
                    start = max(ready, free + tm.travel_to_task(zone, t), starts[t])
                else:
                    start = fixed
                if abs(start - starts[t]) > EPS or ends[t] != start + d:
                    moved = True
                starts[t], ends[t] = start, start + d
                free, zone = max(free, ends[t]), tm.task_zone[t]
        if not moved:
            return starts, ends
    raise ValueError("the robot orders contradict the links: no times keep them all")
