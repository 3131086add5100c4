"""The capped problem over task units as one min-cost flow (docs/allocation.md#teams).

    source -> class of single-robot tasks --(count)--------------------> robot -> sink
    source -> (team task, feature) --(1)--> (team task, robot) --(1)--> robot -> sink

A (team task, robot) gate node lets a robot cover at most one unit of a task, whichever
feature; each robot's arcs to the sink carry the cap's bounds (the lower one as the robot's
demand) and the convex deviation costs of `app.solvers.optimal`. With `optimise` the arcs
cost minus the integer weights of `app.solvers.units` times the deviation factor, so one
solve gives "max success, then least deviation" as for one-robot tasks; without it every
cost is 0 and the solve only answers "can these units still be placed within the cap?"
(greedy and the learners ask that after each choice). Integral, so every unit gets one robot.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from ortools.graph.python import min_cost_flow

from app.domain.errors import InfeasibleCapError
from app.solvers.tiebreak import deviation_arcs
from app.solvers.units import Members, UnitView


@dataclass(frozen=True)
class Item:
    """What is left to place of one free task (position `i` in the view): its unit features
    (() for a single-robot task) and the columns that may no longer cover them (members
    already chosen for it)."""

    i: int
    units: tuple[str, ...] = ()
    excluded: frozenset[int] = frozenset()


class _Network:
    def __init__(self) -> None:
        self.tails: list[int] = []
        self.heads: list[int] = []
        self.caps: list[int] = []
        self.costs: list[int] = []
        self.supplies: list[int] = []

    def node(self, supply: int = 0) -> int:
        self.supplies.append(supply)
        return len(self.supplies) - 1

    def arc(self, tail: int, head: int, capacity: int, cost: int = 0) -> int:
        self.tails.append(tail)
        self.heads.append(head)
        self.caps.append(capacity)
        self.costs.append(cost)
        return len(self.tails) - 1


def place_units(
    view: UnitView,
    items: Sequence[Item],
    loads: Sequence[int],
    *,
    optimise: bool,
) -> dict[int, Members] | None:
    """Per item position: the columns covering its units (one column for a single task),
    from `loads` per column. None when no placement keeps every final load in the cap."""
    cap, r = view.cap, view.n_robots
    lo, hi = cap.lower, cap.upper
    total = sum(len(it.units) or 1 for it in items)
    need = [max(0, lo - x) for x in loads]
    if any(x > hi for x in loads) or sum(need) > total or sum(hi - x for x in loads) < total:
        return None
    net = _Network()
    robot0 = len(net.supplies)
    for c in range(r):
        net.node(-need[c])
    sink = net.node(-(total - sum(need)))
    for c in range(r):
        if optimise:
            for capacity, cost in deviation_arcs(loads[c] + need[c], hi, r, cap.n_tasks):
                net.arc(robot0 + c, sink, capacity, cost)
        elif hi - loads[c] - need[c] > 0:
            net.arc(robot0 + c, sink, hi - loads[c] - need[c])
    factor = view.factor if optimise else 0
    singles = [it for it in items if not it.units]
    class_arcs = _single_classes(view, net, singles, robot0, factor, optimise)
    unit_arcs: dict[int, list[tuple[str, int, int]]] = {}
    for it in items:
        if it.units:
            unit_arcs[it.i] = _team_nodes(view, net, it, robot0, factor)
    flow = min_cost_flow.SimpleMinCostFlow()
    if net.tails:
        flow.add_arcs_with_capacity_and_unit_cost(
            np.array(net.tails), np.array(net.heads), np.array(net.caps), np.array(net.costs)
        )
    flow.set_nodes_supplies(np.arange(len(net.supplies)), np.array(net.supplies))
    if not net.tails or flow.solve() != flow.OPTIMAL:
        return None if total else {}
    out: dict[int, Members] = {}
    for members, pairs in class_arcs:
        queue = [c for arc, c in pairs for _ in range(flow.flow(arc))]
        for i, c in zip(members, queue, strict=True):
            out[i] = (c,)
    for i, arcs in unit_arcs.items():
        item = next(it for it in items if it.i == i)
        chosen: dict[str, list[int]] = {}
        for feature, arc, c in arcs:
            if flow.flow(arc):
                chosen.setdefault(feature, []).append(c)
        out[i] = tuple(c for f in dict.fromkeys(item.units) for c in sorted(chosen[f]))
    return out


def _single_classes(
    view: UnitView,
    net: _Network,
    singles: Sequence[Item],
    robot0: int,
    factor: int,
    optimise: bool,
) -> list[tuple[list[int], list[tuple[int, int]]]]:
    """One node per class of interchangeable single tasks (equal weights and eligibility);
    returns per class its task positions (queue order) and its (arc, column) pairs."""
    groups: dict[bytes, list[int]] = {}
    for it in singles:
        key = view.eligible[it.i].tobytes()
        if optimise:
            key += view.single_weights[it.i].tobytes()
        groups.setdefault(key, []).append(it.i)
    out = []
    for members in groups.values():
        node = net.node(len(members))
        first = members[0]
        weights = view.single_weights[first]
        arcs = [
            (net.arc(node, robot0 + c, len(members), -int(weights[c]) * factor), c)
            for c in view.single_columns(first)
        ]
        out.append((members, arcs))  # robot order: earlier tasks on lower columns
    return out


def _team_nodes(
    view: UnitView, net: _Network, item: Item, robot0: int, factor: int
) -> list[tuple[str, int, int]]:
    gates: dict[int, int] = {}
    arcs = []
    for feature in dict.fromkeys(item.units):
        node = net.node(item.units.count(feature))
        for c in view.unit_columns(item.i, feature):
            if c in item.excluded:
                continue
            if c not in gates:
                gates[c] = net.node()
                net.arc(gates[c], robot0 + c, 1)
            cost = -view.unit_weight(item.i, feature, c) * factor
            arcs.append((feature, net.arc(node, gates[c], 1, cost), c))
    return arcs


def best_units(view: UnitView) -> list[Members]:
    """The exact optimum: one choice per free task, in queue order."""
    items = [Item(i, view.units[i]) for i in range(len(view.tasks))]
    placed = place_units(view, items, view.initial_loads, optimise=True)
    if placed is None:
        view.cap.ensure_feasible()
        raise InfeasibleCapError(
            f"no plan gives every unit of the {len(items)} free tasks a distinct eligible robot "
            f"within [{view.cap.lower}, {view.cap.upper}] tasks per robot; raise max_deviation "
            "or lower a team's counts"
        )
    return [placed[i] for i in range(len(items))]
