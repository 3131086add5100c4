"""Earliest-finish dispatch: choose robots while scheduling, within per-class quotas.

The list scheduler times a fixed assignment. When only *how many* tasks of each class
each robot takes is fixed (the exact allocation optimum fixes exactly that: tasks of one
class are interchangeable for expected success and the cap), which robot takes which task
is free, and choosing it in time order gives far better schedules: each task, taken in
the list scheduler's order (earliest possible start first), goes to the robot with quota
left for its class that would finish it first (ties: robot order). Every quota is used
exactly, so the assignment has the same expected success and loads as the one the
quotas came from. It is a heuristic (an incumbent and a hint for CP-SAT, and what the
LTAA graph can read "next free" times from), not an optimum.
"""

from __future__ import annotations

import heapq
from collections.abc import Mapping, Sequence

from app.domain.problem import Problem
from app.domain.scheduling.list_schedule import Timeline
from app.domain.scheduling.schedule import EPS, Schedule, build_schedule


def quotas_of(assignment: Sequence[int], classes: Sequence[int]) -> dict[tuple[int, int], int]:
    """(class, robot) -> how many tasks of the class the assignment gives the robot."""
    out: dict[tuple[int, int], int] = {}
    for t, r in enumerate(assignment):
        out[classes[t], r] = out.get((classes[t], r), 0) + 1
    return out


def dispatch_schedule(
    problem: Problem,
    classes: Sequence[int],
    quotas: Mapping[tuple[int, int], int],
    penalty: Sequence[float] | None = None,
    slowness: float = 0.0,
) -> Schedule:
    """Schedule every task, choosing its robot among those with quota left for its class
    (`classes[t]`); pinned tasks keep their robot (and count against its quota).
    `penalty[r]` lengthens robot r's durations by that share when choosing (not when
    timing): a busy robot then takes the tasks it is quick at. `slowness` charges a choice
    that many minutes per minute its robot is slower at the task than the quickest robot
    open to it: where robots' speeds are unrelated (docs/schedules.md#the-generator), the
    earliest finish alone hands a task to a slow robot free now over a quick one free a
    little later, and the plan runs long on slow work."""
    tm = problem.instance.timing
    n = tm.n_tasks
    left = dict(quotas)
    robots_of: dict[int, list[int]] = {}
    for c, r in sorted(quotas):
        robots_of.setdefault(c, []).append(r)
    robot = [-1] * n
    starts, ends, done = [0.0] * n, [0.0] * n, [False] * n
    lines = [Timeline(a, tm.robot_zone[r]) for r, (a, _) in enumerate(tm.shifts)]
    for t, r in problem.pinned.items():
        robot[t] = r
        left[classes[t], r] -= 1
    for t, start in sorted(problem.pinned_starts.items(), key=lambda item: item[1]):
        r = robot[t]
        lines[r].fixed.append((start, start + tm.duration(t, r), t))
        starts[t], ends[t], done[t] = start, start + tm.duration(t, r), True
    waiting = [sum(1 for p in tm.predecessors[t] if not done[p]) for t in range(n)]

    def choices(t: int) -> list[int]:
        if robot[t] >= 0:
            return [robot[t]]
        return [r for r in robots_of.get(classes[t], []) if left[classes[t], r] > 0]

    def best(t: int) -> tuple[float, float, int]:
        floor = max(tm.release[t], problem.not_before)
        options = []
        open_to = choices(t)
        quickest = min((tm.duration(t, r) for r in open_to), default=0.0)
        for r in open_to:
            ready = max(tm.ready(t, tm.duration(t, r), starts, ends), floor)
            s = lines[r].earliest(tm, t, r, ready)
            slower = 1.0 if penalty is None else 1.0 + penalty[r]
            excess = slowness * (tm.duration(t, r) - quickest)
            options.append((s + tm.duration(t, r) * slower + excess, s, r))
        if not options:
            raise ValueError(f"no robot has quota left for task {t} (class {classes[t]})")
        finish, s, r = min(options)
        return s, finish, r

    heap = [(best(t)[0], t) for t in range(n) if not done[t] and waiting[t] == 0]
    heapq.heapify(heap)
    while heap:
        est, t = heapq.heappop(heap)
        s, _, r = best(t)
        if s > est + EPS:  # robots filled up or quotas ran out since: look again later
            heapq.heappush(heap, (s, t))
            continue
        lines[r].place(tm, t, r, s)
        if robot[t] < 0:
            robot[t] = r
            left[classes[t], r] -= 1
        starts[t], ends[t], done[t] = s, s + tm.duration(t, r), True
        for u in tm.successors[t]:
            waiting[u] -= 1
            if waiting[u] == 0 and not done[u]:
                heapq.heappush(heap, (best(u)[0], u))
    if not all(done):
        raise ValueError("some task was never ready; the precedence graph is broken")
    return build_schedule(problem, robot, starts, ends)
