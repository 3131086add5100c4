"""One definition of "optimal" for every exact method.

Maximise the sum of S subject to the cap; among equal sums prefer the lower sum of
|d_r|; among those, robot order. Every exact solver compares the same integers: S scaled
to integer weights (1e-9 resolution on small instances, see `weight_scale`), and the
deviation as R*|L_r - W| = |R*L_r - n|. So "equal" means the same thing in brute force,
the DP and the min-cost flow, and they cannot disagree on near-ties.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

MAX_SCALE = 10**9
COST_BUDGET = 10**17  # keeps every min-cost-flow cost sum far inside int64


def deviation_factor(n_tasks: int, n_robots: int) -> int:
    """Exceeds any difference in total deviation units, so weights dominate deviation."""
    return 2 * n_robots * max(n_tasks, 1) + 1


def weight_scale(n_tasks: int, n_robots: int, rows: int | None = None) -> int:
    """Integer weight per unit of S: 1e9 unless int64 cost sums need it smaller."""
    rows = n_tasks if rows is None else rows
    factor = deviation_factor(n_tasks, n_robots)
    return max(1, min(MAX_SCALE, COST_BUDGET // (factor * max(rows, 1))))


def integer_weights(success: np.ndarray, scale: int) -> np.ndarray:
    return np.rint(success * scale).astype(np.int64)


def deviation_units(loads: Sequence[int], n_tasks: int) -> int:
    r = len(loads)
    return sum(abs(r * load - n_tasks) for load in loads)


def better(value: int, dev: int, best_value: int, best_dev: int) -> bool:
    """Is (value, dev) strictly preferable to the incumbent? Ties keep the incumbent."""
    return value > best_value or (value == best_value and dev < best_dev)


def deviation_arcs(load_from: int, load_to: int, r: int, n: int) -> list[tuple[int, int]]:
    """(capacity, unit cost) arcs for raising a load from load_from to load_to.

    Marginal cost of the k -> k+1 step is |R(k+1) - n| - |Rk - n|: -R below the target,
    +R above, something between at the crossing. Convex, so min-cost flow fills in order.
    Counted in closed form (at most three arcs): the step-by-step count was O(load range)
    per flow, so a run's per-decision regret cost O(n) each, O(n^2) over the run.
    """
    arcs: dict[int, int] = {}
    below = min(load_to, n // r) - load_from  # steps with R(k+1) <= n
    if below > 0:
        arcs[-r] = below
    if n % r and load_from <= n // r < load_to:  # the one step across the target
        k = n // r
        arcs[r * (2 * k + 1) - 2 * n] = 1
    above = load_to - max(load_from, -(-n // r))  # steps with Rk >= n
    if above > 0:
        arcs[r] = above
    return sorted(((cap, cost) for cost, cap in arcs.items()), key=lambda a: a[1])
