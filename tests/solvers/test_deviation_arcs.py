"""The min-cost flow's deviation arcs in closed form equal the step-by-step count they
replaced (so the optimum, the guidance and every per-decision regret are unchanged)."""

from __future__ import annotations

from app.solvers.optimal import _deviation_arcs


def stepwise(load_from: int, load_to: int, r: int, n: int) -> list[tuple[int, int]]:
    arcs: dict[int, int] = {}
    for k in range(load_from, load_to):
        step = abs(r * (k + 1) - n) - abs(r * k - n)
        arcs[step] = arcs.get(step, 0) + 1
    return sorted(((cap, cost) for cost, cap in arcs.items()), key=lambda a: a[1])


def test_closed_form_equals_the_step_by_step_count() -> None:
    for r in range(1, 7):
        for n in range(0, 40):
            for load_from in range(0, 15):
                for load_to in range(load_from, 18):
                    assert _deviation_arcs(load_from, load_to, r, n) == stepwise(
                        load_from, load_to, r, n
                    ), (load_from, load_to, r, n)


def test_large_ranges_are_three_arcs_at_most() -> None:
    arcs = _deviation_arcs(0, 2_600, 4, 10_001)
    assert arcs == stepwise(0, 2_600, 4, 10_001) and len(arcs) == 3
