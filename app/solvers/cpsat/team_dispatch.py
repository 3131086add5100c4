"""A first team schedule for the team model's search (docs/schedules.md#teams-in-time): serial
schedule generation by the longest tail, each team formed of the robots free soonest.

The time-free optimum's list schedule is the other start, and on instances where every plan
has the same expected success (MSPSP-InstLib's) its teams are arbitrary and its makespan far
from the optimum. Here: tasks are placed one at a time, among those whose predecessors are
placed the one with the longest chain of work after it (the classic latest-finish rule); a
single-robot task on the able robot that finishes it first, a team on the distinct able robots
whose latest free time is least (a matching per unit's feature). Only orders and teams come
out: `sequence_schedule` times them exactly (travel, shifts), and the caller keeps the plan
only if it passes the feasibility check.
"""

from __future__ import annotations

from collections.abc import Sequence

from app.domain.problem import Problem
from app.domain.teams import covers, unit_matching


def team_dispatch(
    problem: Problem, candidates: Sequence[Sequence[int]]
) -> tuple[list[list[int]], dict[int, tuple[int, ...]]] | None:
    """Per robot its tasks in order and each team's robot per unit; None where pins make
    the instance not this heuristic's (the model's own search handles them)."""
    if problem.pinned or problem.pinned_starts:
        return None
    tm, instance = problem.instance.timing, problem.instance
    units = instance.units
    n = tm.n_tasks
    tail = [0.0] * n
    for t in reversed(tm.order):
        after = [tail[u] for u in tm.successors[t]]
        tail[t] = tm.shortest(t) + max(after, default=0.0)
    free = [a for a, _ in tm.shifts]
    starts, ends = [0.0] * n, [0.0] * n
    waiting = [len(p) for p in tm.predecessors]
    ready = [t for t in range(n) if not waiting[t]]
    sequences: list[list[int]] = [[] for _ in range(tm.n_robots)]
    teams: dict[int, tuple[int, ...]] = {}
    while ready:
        t = max(ready, key=lambda k: (tail[k], -k))
        ready.remove(t)
        est = max(tm.release[t], problem.not_before, tm.ready(t, tm.shortest(t), starts, ends))
        if units[t]:
            members = _team(problem, t, candidates[t], free)
            if members is None:
                return None
            teams[t] = members
        else:
            members = (
                min(candidates[t], key=lambda r: (max(free[r], est) + tm.duration(t, r), r)),
            )
        starts[t] = max([est, *(free[r] for r in members)])
        ends[t] = starts[t] + tm.duration(t, members[0])
        for r in set(members):
            free[r] = ends[t]
            sequences[r].append(t)
        for u in tm.successors[t]:
            waiting[u] -= 1
            if not waiting[u]:
                ready.append(u)
    return sequences, teams


def _team(
    problem: Problem, t: int, able: Sequence[int], free: Sequence[float]
) -> tuple[int, ...] | None:
    """Distinct robots covering task t's units (in unit order) whose latest free time is
    least: the first threshold of free times at which a matching covers every unit."""
    robots, feature_of = problem.instance.robots, problem.instance.units[t]
    options = [[r for r in able if covers(robots[r], f)] for f in feature_of]
    for limit in sorted({free[r] for r in able}):
        allowed = [
            sorted((r for r in o if free[r] <= limit), key=lambda r: (free[r], r)) for o in options
        ]
        match = _matching(allowed)
        if match is not None:
            return tuple(match)
    return None


def _matching(options: Sequence[Sequence[int]]) -> list[int] | None:
    """A robot per unit, all distinct, or None where no such team exists."""
    holder = unit_matching(options)
    if len(holder) < len(options):
        return None
    out = [0] * len(options)
    for r, unit in holder.items():
        out[unit] = r
    return out
