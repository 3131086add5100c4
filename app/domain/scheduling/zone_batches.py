"""Per-robot orders for a fixed assignment that keep a robot in one zone for a run of
tasks (docs/schedules.md#anytime): the zone-batching list schedule.

The serial list scheduler (`list_schedule`) takes the tasks in queue order, so a robot
whose tasks lie in four zones crosses the site as often as its queue says. Here the
robot that is free first picks its next task among its own ready ones (every
predecessor placed), by its start, plus `travel_weight` times the way there (staying in
the zone is worth that many minutes of waiting per minute of travel), less `tail_weight`
times the task's tail (the chain of work after it: the others wait for it). The
simulated times only rank the choices: the orders are timed afresh by
`sequence_schedule`, which holds every rule.
"""

from __future__ import annotations

from collections.abc import Sequence

from app.domain.problem import Problem


def batched_orders(
    problem: Problem,
    assignment: Sequence[int],
    tails: Sequence[float],
    travel_weight: float,
    tail_weight: float,
) -> list[list[int]]:
    """Each robot's tasks of `assignment` in the order the zone-batching rule picks them.
    For a plan without fixed starts (facts): `sequence_schedule` times the orders."""
    tm = problem.instance.timing
    n, m = tm.n_tasks, tm.n_robots
    free = [max(a, problem.not_before) for a, _ in tm.shifts]
    zone = list(tm.robot_zone)
    starts, ends = [0.0] * n, [0.0] * n
    waiting = [len(tm.predecessors[t]) for t in range(n)]
    ready: list[set[int]] = [set() for _ in range(m)]
    for t in range(n):
        if waiting[t] == 0:
            ready[assignment[t]].add(t)
    orders: list[list[int]] = [[] for _ in range(m)]
    for _ in range(n):
        # The robot free first among those with a ready task; ties to the lower index.
        r = min((q for q in range(m) if ready[q]), key=lambda q: (free[q], q))
        best: tuple[float, float, int] | None = None
        for t in ready[r]:
            d = tm.duration(t, r)
            way = tm.travel_to_task(zone[r], t)
            s = max(free[r] + way, tm.ready(t, d, starts, ends), tm.release[t])
            key = (s + travel_weight * way - tail_weight * tails[t], s, t)
            if best is None or key < best:
                best = key
        assert best is not None  # r has a ready task
        _, s, t = best
        starts[t], ends[t] = s, s + tm.duration(t, r)
        free[r], zone[r] = ends[t], tm.task_zone[t]
        ready[r].discard(t)
        orders[r].append(t)
        for u in tm.successors[t]:
            waiting[u] -= 1
            if waiting[u] == 0:
                ready[assignment[u]].add(u)
    return orders
