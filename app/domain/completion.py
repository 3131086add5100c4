"""Can the tasks still to place each get an eligible robot within the cap?

Counting loads (`WorkloadCap.can_complete`) answers this when every robot may take every
task. With eligibility restrictions (robots' skills, docs/allocation.md#teams, or a timed
task's duration map) it is a bipartite flow: tasks to the robots that may take them, each
robot receiving between its shortfall to the cap's lower bound and its room to the upper
bound. The methods that place one task at a time (the learners, the LTAA graph) ask this
before offering a robot, so they never walk into a queue they cannot finish.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def completable(eligible: np.ndarray, loads: Sequence[int], lower: int, upper: int) -> bool:
    """eligible: (tasks left, robots); loads: per robot so far. A max flow source -> task
    classes -> robots -> sink where each robot's first `lower - load` units go straight to
    the sink and the rest through one shared node capped at the units left over: the flow
    saturates iff some placement gives every robot a final load in [lower, upper]."""
    from scipy.sparse import csr_array
    from scipy.sparse.csgraph import maximum_flow

    m, r = eligible.shape
    need = [max(0, lower - x) for x in loads]
    room = [upper - x for x in loads]
    if min(room, default=0) < 0 or sum(need) > m or sum(room) < m:
        return False
    if m == 0:
        return True
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
