"""One definition of "optimal" for every exact method.

Maximise the sum of S subject to the cap; among equal sums prefer the lower sum of
|d_r|; among those, the lexicographically smallest robot sequence in queue order.
Deviation is kept as the integer R*|L_r - W| = |R*L_r - n| so comparisons are exact.
"""

from __future__ import annotations

from collections.abc import Sequence

# Sums of S closer than this are the same sum (floating-point order of addition).
SUM_TOLERANCE = 1e-9


def deviation_units(loads: Sequence[int], n_tasks: int) -> int:
    r = len(loads)
    return sum(abs(r * load - n_tasks) for load in loads)


def better(value: float, dev: int, best_value: float, best_dev: int) -> bool:
    """Is (value, dev) strictly preferable to the incumbent? Ties keep the incumbent."""
    if value > best_value + SUM_TOLERANCE:
        return True
    return abs(value - best_value) <= SUM_TOLERANCE and dev < best_dev
