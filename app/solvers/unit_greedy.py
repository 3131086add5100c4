"""Greedy over task units (docs/allocation.md#teams): task by task, and in a team unit by
unit, the eligible robot with the highest rate (ties: robot order) that is not yet in the
team and whose choice still lets every later unit get a distinct eligible robot within the
cap. That last check is a feasibility flow (`app.solvers.unit_flow`) over what is left, so
it holds on instances where counting loads alone would paint greedy into a corner: a team
needing two robots with room when only one has any, a task only busy robots may take.
"""

from __future__ import annotations

from collections.abc import Sequence

from app.domain.errors import InfeasibleCapError
from app.solvers.base import Solution
from app.solvers.unit_flow import Item, place_units
from app.solvers.units import Members, UnitView


def greedy_units(view: UnitView) -> Solution:
    n = len(view.tasks)
    later = [Item(i, view.units[i]) for i in range(n)]
    loads = list(view.initial_loads)
    if place_units(view, later, loads, optimise=False) is None:
        view.cap.ensure_feasible()
        raise InfeasibleCapError(
            "no plan gives every task (every unit of a team) a distinct eligible robot within "
            f"the cap's [{view.cap.lower}, {view.cap.upper}] tasks per robot; raise max_deviation"
        )
    choices: list[Members] = []
    for i in range(n):
        choices.append(_choose(view, i, loads, later[i + 1 :]))
    return view.solution(choices, {})


def _choose(view: UnitView, i: int, loads: list[int], rest: Sequence[Item]) -> Members:
    """The choice for free task i; updates `loads`."""
    robots = view.problem.instance.robots
    units = view.units[i]
    if not units:
        weights = view.single_weights[i]
        ranked = sorted(view.single_columns(i), key=lambda c: -int(weights[c]))
        c = _first_feasible(view, ranked, loads, list(rest))
        return (c,)
    members: list[int] = []
    for u, feature in enumerate(units):
        ranked = sorted(
            (c for c in view.unit_columns(i, feature) if c not in members),
            key=lambda c: -robots[view.robots[c]].success[feature],
        )
        c = _first_feasible(view, ranked, loads, list(rest), (i, units[u + 1 :], members))
        members.append(c)
    # Units of one feature are interchangeable: their members in robot order.
    return tuple(
        c
        for f in dict.fromkeys(units)
        for c in sorted(m for m, g in zip(members, units, strict=True) if g == f)
    )


def _first_feasible(
    view: UnitView,
    ranked: Sequence[int],
    loads: list[int],
    rest: list[Item],
    team: tuple[int, tuple[str, ...], list[int]] | None = None,
) -> int:
    """The first of `ranked` after which what is left still fits; `team`: (task, its units
    still to cover, its members so far), when choosing a member of a team."""
    for c in ranked:
        items = rest
        if team is not None and team[1]:
            items = [Item(team[0], team[1], frozenset([*team[2], c])), *rest]
        loads[c] += 1
        remaining = sum(len(it.units) or 1 for it in items)
        if view.cap.can_complete(loads, remaining) and (
            place_units(view, items, loads, optimise=False) is not None
        ):
            return c
        loads[c] -= 1
    raise InfeasibleCapError("no eligible robot keeps the cap satisfiable for this task")
