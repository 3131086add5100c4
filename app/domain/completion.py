"""Can the tasks still to place each get an eligible robot within the cap?

Counting loads (`WorkloadCap.can_complete`) answers this when every robot may take every
task. With eligibility restrictions (robots' skills, docs/allocation.md#teams, or a timed
task's duration map) it is a bipartite flow: tasks to the robots that may take them, each
robot receiving between its shortfall to the cap's lower bound and its room to the upper
bound. The methods that place one task at a time (the learners, the LTAA graph) ask this
before offering a robot, so they never walk into a queue they cannot finish.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np


def _counts(
    loads: Sequence[int], lower: int, upper: int, m: int
) -> tuple[list[int], list[int], bool | None]:
    """Per robot its shortfall to `lower` and its room to `upper`, and the answer when
    counting `m` units alone settles it (None: the flow must tell)."""
    need = [max(0, lower - x) for x in loads]
    room = [upper - x for x in loads]
    if min(room, default=0) < 0 or sum(need) > m or sum(room) < m:
        return need, room, False
    return need, room, (True if m == 0 else None)


def completable(eligible: np.ndarray, loads: Sequence[int], lower: int, upper: int) -> bool:
    """eligible: (tasks left, robots); loads: per robot so far. A max flow source -> task
    classes -> robots -> sink where each robot's first `lower - load` units go straight to
    the sink and the rest through one shared node capped at the units left over: the flow
    saturates iff some placement gives every robot a final load in [lower, upper]."""
    from scipy.sparse import csr_array
    from scipy.sparse.csgraph import maximum_flow

    m, r = eligible.shape
    need, room, settled = _counts(loads, lower, upper, m)
    if settled is not None:
        return settled
    rows, counts = np.unique(eligible, axis=0, return_counts=True)
    c = len(rows)
    source, spare, sink = 0, 1 + c + r, 2 + c + r
    tails, heads, caps = [], [], []

    def arc(a: int, b: int, capacity: int) -> None:
        if capacity > 0:
            tails.append(a)
            heads.append(b)
            caps.append(capacity)

    for k in range(c):
        arc(source, 1 + k, int(counts[k]))
        for col in np.flatnonzero(rows[k]):
            arc(1 + k, 1 + c + int(col), int(counts[k]))
    for j in range(r):
        arc(1 + c + j, sink, need[j])
        arc(1 + c + j, spare, room[j] - need[j])
    arc(spare, sink, m - sum(need))
    graph = csr_array(
        (np.array(caps, dtype=np.int32), (np.array(tails), np.array(heads))),
        shape=(sink + 1, sink + 1),
    )
    return int(maximum_flow(graph, source, sink).flow_value) == m


# A team task still to place: per feature, (count, which robots may cover it); a robot covers
# at most one unit of the task (docs/allocation.md#teams).
TeamLeft = Sequence[tuple[int, np.ndarray]]


def units_completable(
    singles: np.ndarray,
    teams: Sequence[TeamLeft],
    loads: Sequence[int],
    lower: int,
    upper: int,
) -> bool:
    """`completable` with team tasks among those left: each team task's features get their
    counts of distinct robots, through a (task, robot) gate of capacity 1 per robot. The
    same max flow otherwise, so it saturates iff a placement within [lower, upper] exists.

    k identical team tasks share one set of nodes: per feature k x count units, and a gate
    of capacity k per robot. Exact: split each feature into `count` slots of k units; the
    flow is then a bipartite multigraph of maximum degree k between slots and robots, which
    by Koenig's edge-colouring theorem splits into k matchings, one team per task."""
    from scipy.sparse import csr_array
    from scipy.sparse.csgraph import maximum_flow

    r = len(loads)
    m = len(singles) + sum(count for team in teams for count, _ in team)
    need, room, settled = _counts(loads, lower, upper, m)
    if settled is not None:
        return settled
    tails: list[int] = []
    heads: list[int] = []
    caps: list[int] = []
    count = [3 + r]  # next free node: 0 source, 1 spare, 2 sink, 3.. robots

    def node() -> int:
        count[0] += 1
        return count[0] - 1

    def arc(a: int, b: int, capacity: int) -> None:
        if capacity > 0:
            tails.append(a)
            heads.append(b)
            caps.append(capacity)

    source, spare, sink = 0, 1, 2
    if len(singles):
        rows, counts = np.unique(singles, axis=0, return_counts=True)
        for row, n in zip(rows, counts, strict=True):
            k = node()
            arc(source, k, int(n))
            for col in np.flatnonzero(row):
                arc(k, 3 + int(col), int(n))
    alike: dict[tuple[tuple[int, bytes], ...], tuple[TeamLeft, int]] = {}
    for team in teams:
        key = tuple((n, mask.tobytes()) for n, mask in team)
        alike[key] = (team, alike[key][1] + 1 if key in alike else 1)
    for team, copies in alike.values():
        gates: dict[int, int] = {}
        for n, mask in team:
            k = node()
            arc(source, k, n * copies)
            for col in np.flatnonzero(mask):
                c = int(col)
                if c not in gates:
                    gates[c] = node()
                    arc(gates[c], 3 + c, copies)
                arc(k, gates[c], copies)
    for j in range(r):
        arc(3 + j, sink, need[j])
        arc(3 + j, spare, room[j] - need[j])
    arc(spare, sink, m - sum(need))
    size = count[0]
    graph = csr_array(
        (np.array(caps, dtype=np.int32), (np.array(tails), np.array(heads))), shape=(size, size)
    )
    return int(maximum_flow(graph, source, sink).flow_value) == m


class CompletionMemo:
    """The completion check's answers for the states asked again (the graph asks the same one
    several times per task). Answers keyed by a queue position are kept up to `size`; answers
    for a named list of tasks still to decide (a timed run's order) only while that list is
    the current one: it changes with every decision, and keys holding whole task lists grew
    with the square of the run's length."""

    def __init__(self, size: int = 4096) -> None:
        self._size = size
        self._by_position: dict[tuple[int, tuple[int, ...]], bool] = {}
        self._later: tuple[int, ...] | None = None
        self._by_loads: dict[tuple[int, ...], bool] = {}

    def answer(
        self,
        position: int,
        later: Sequence[int] | None,
        loads: tuple[int, ...],
        compute: Callable[[], bool],
    ) -> bool:
        if later is not None:
            current = tuple(later)
            if current != self._later:
                self._later, self._by_loads = current, {}
            if loads not in self._by_loads:
                self._by_loads[loads] = compute()
            return self._by_loads[loads]
        key = (position, loads)
        if key not in self._by_position:
            self._by_position[key] = compute()
            if len(self._by_position) > self._size:  # a run moves forward: the oldest go
                self._by_position.pop(next(iter(self._by_position)))
        return self._by_position[key]
