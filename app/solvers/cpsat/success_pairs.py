"""Which (task, robot) pairs occur in some allocation of maximal expected success?

When a schedule reaches the time-free ES optimum (the min-cost flow's), stage 2 of
`success_then_makespan` may only use pairs that some ES-optimal allocation uses: any
other pair would lower the ES. Removing the rest before CP-SAT sees the model shrinks it
a lot (on the paper's instance most tasks keep one or two robots). Exact: a pair of task
class c and robot r is kept iff forcing one task of c onto r still reaches the optimum
(one small min-cost flow per class and robot; classes group interchangeable tasks).
"""

from __future__ import annotations

import numpy as np

from app.domain.errors import InfeasibleCapError
from app.domain.problem import Problem
from app.solvers.free_part import FreePart
from app.solvers.optimal import TaskClasses, class_allocation
from app.solvers.tiebreak import integer_weights, weight_scale


def success_optimal_pairs(problem: Problem) -> set[tuple[int, int]]:
    """(task index, robot index) pairs, fleet-wide, that some ES-optimal allocation under
    the cap uses. Pinned tasks keep their pin."""
    part = FreePart.of(problem)
    eligible = part.eligible
    classes = TaskClasses.of(part.success, None if eligible.all() else eligible)
    n_classes, n_cols = classes.rows.shape
    first = [int(np.argmax(classes.of_task == c)) for c in range(n_classes)]
    allowed = eligible[first]
    counts = classes.counts()
    scale = weight_scale(part.cap.n_tasks, part.cap.n_robots, part.n_tasks)
    weight = integer_weights(classes.rows, scale)
    init = list(part.initial_loads)
    base = class_allocation(classes.rows, counts, part.cap, init, allowed)
    best = int((base * weight).sum())
    usable = base > 0
    for c in range(n_classes):
        for r in range(n_cols):
            if usable[c, r] or not allowed[c, r]:
                continue
            forced_counts = counts.copy()
            forced_counts[c] -= 1
            forced_init = list(init)
            forced_init[r] += 1
            try:
                x = class_allocation(classes.rows, forced_counts, part.cap, forced_init, allowed)
            except InfeasibleCapError:
                continue
            usable[c, r] = int((x * weight).sum()) + int(weight[c, r]) == best
    robots = problem.available if (problem.pinned or problem.unavailable) else None
    pairs = {(t, r) for t, r in problem.pinned.items()}
    for i, t in enumerate(problem.free_tasks):
        c = classes.of_task[i]
        for col in np.flatnonzero(usable[c]):
            pairs.add((t, int(col) if robots is None else robots[int(col)]))
    return pairs
