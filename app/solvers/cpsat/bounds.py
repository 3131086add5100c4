"""Lower bounds on the makespan that hold for every schedule, named by where they come from.

Each is a relaxation the search never has to prove again (the exact model starts from the
largest, `makespan >= floor`), and each answer says which one bounds its `bound`:

- `critical path (shortest durations)`: the longest chain of precedence, each task at its
  shortest duration, from the releases, `not_before` and the earliest any robot able to
  take the task can be there (its shift start plus the way from its start zone);
- `heads and tails over the robots able` (the redundant cumulative reasoning, computed
  here rather than in the model): for a group of robots and the tasks only they may take,
  those tasks that cannot start before `h` (their head) and leave at least `q` of chain
  behind them (their tail) need their shortest work inside [h, makespan - q] on those
  robots, each from its shift start: makespan >= q + (work + sum of max(h, shift start))
  / robots. Groups: all robots (total demand), and each distinct set of robots able (the
  per-feature / eligibility groups; one machine alone gives the one-machine bound).
"""

from __future__ import annotations

from collections import Counter
from typing import NamedTuple

import numpy as np

from app.domain.links import tail_through
from app.domain.problem import Problem

CRITICAL_PATH = "critical path (shortest durations)"
HEADS_TAILS = "heads and tails over the robots able"
MAX_GROUPS = 40  # distinct eligibility sets examined (the most common first)


class Chains(NamedTuple):
    """Per task: the robots able (within `pairs`), its shortest duration, its head (the
    earliest it can start), its tail (the least chain of work after it ends) and the
    earliest it can end (a finish link can hold an end later than head + shortest)."""

    options: list[list[int]]
    shortest: np.ndarray
    heads: np.ndarray
    tails: np.ndarray
    ends: np.ndarray


def chains(problem: Problem, pairs: set[tuple[int, int]] | None = None) -> Chains:
    """The heads, tails and ends of every task (`Chains`), within `pairs`."""
    tm = problem.instance.timing
    n = tm.n_tasks
    options = [_options(problem, t, pairs) for t in range(n)]
    shortest = np.array([min(tm.duration(t, r) for r in options[t]) for t in range(n)])
    longest = [max(tm.duration(t, r) for r in options[t]) for t in range(n)]
    heads, ends = np.zeros(n), np.zeros(n)
    for t in tm.order:
        fixed = problem.pinned_starts.get(t)
        if fixed is not None:
            heads[t], ends[t] = fixed, fixed + shortest[t]
            continue
        there = min(tm.shifts[r][0] + tm.travel_to_task(tm.robot_zone[r], t) for r in options[t])
        # docs/schedules.md#links: the longest duration bounds a start, the shortest an end
        ready = tm.ready(t, longest[t], heads, ends)
        heads[t] = max(ready, tm.release[t], problem.not_before, there)
        ends[t] = max(tm.ready(t, shortest[t], heads, ends) + shortest[t], heads[t] + shortest[t])
    tails = np.zeros(n)
    for t in reversed(tm.order):
        tails[t] = max(
            (
                tail_through(arc, longest[t], shortest[s], tails[s])
                for s, arc in tm.successor_links[t]
                if s not in problem.pinned_starts
            ),
            default=0.0,
        )
    return Chains(options, shortest, heads, tails, ends)


def bound_floors(problem: Problem, pairs: set[tuple[int, int]] | None = None) -> dict[str, float]:
    """Named lower bounds (minutes) on the makespan of any schedule using only `pairs`."""
    tm = problem.instance.timing
    n = tm.n_tasks
    options, shortest, heads, tails, ends = chains(problem, pairs)
    out = {CRITICAL_PATH: float(np.max(ends + tails, initial=0.0))}
    free = np.array([t not in problem.pinned_starts for t in range(n)])
    sets = Counter(frozenset(o) for t, o in enumerate(options) if free[t])
    groups = [frozenset(r for o in sets for r in o)]
    groups += [s for s, _ in sets.most_common(MAX_GROUPS) if s != groups[0]]
    best = 0.0
    for group in groups:
        inside = free & np.array([set(o) <= group for o in options])
        if inside.any():
            starts = np.array([tm.shifts[r][0] for r in sorted(group)])
            best = max(best, _heads_tails(heads[inside], tails[inside], shortest[inside], starts))
    out[HEADS_TAILS] = best
    return out


def _options(problem: Problem, t: int, pairs: set[tuple[int, int]] | None) -> list[int]:
    pin = problem.pinned.get(t)
    if pin is not None:
        return [pin]
    return [
        r
        for r in problem.instance.timing.eligible_robots(t)
        if r not in problem.unavailable and (pairs is None or (t, r) in pairs)
    ]


def _heads_tails(
    heads: np.ndarray, tails: np.ndarray, work: np.ndarray, starts: np.ndarray
) -> float:
    m = len(starts)
    order = np.argsort(-tails, kind="stable")
    heads, tails, work = heads[order], tails[order], work[order]
    best = 0.0
    for h in np.unique(heads):
        keep = heads >= h
        w = np.cumsum(work[keep])  # tails descending: the first k have the k largest
        q = tails[keep]
        # at each distinct tail q, all tasks with tail >= q: the last index with that tail
        last = np.r_[q[1:] != q[:-1], True]
        capacity = np.maximum(h, starts).sum()
        best = max(best, float(np.max(q[last] + (w[last] + capacity) / m)))
    return best


def best_bound(floors: dict[str, float], makespan: float, proven: bool) -> tuple[float, str]:
    """(bound, what bounds it): the largest floor, never above the best makespan."""
    if proven:
        return makespan, "proven optimal"
    source = max(floors, key=lambda k: floors[k])
    return min(makespan, floors[source]), source
