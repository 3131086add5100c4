"""Brute force and the DP over task units (docs/allocation.md#teams): exact on instances with
team tasks or eligibility restrictions, where a task's choices are `UnitView.options` (its
eligible robots, or its eligible teams of distinct robots) rather than every robot.

Both compare the integer weights and deviation units every exact solver uses, and both keep
the first best choice in robot order, as their one-robot versions do.
"""

from __future__ import annotations

import math

import numpy as np

from app.domain.errors import InfeasibleCapError, TooLargeError
from app.solvers.tiebreak import better, deviation_units
from app.solvers.units import Members, UnitView

Loads = tuple[int, ...]


def _no_completion(view: UnitView) -> InfeasibleCapError:
    view.cap.ensure_feasible()
    return InfeasibleCapError(
        "no plan gives every task (every unit of a team) a distinct eligible robot within the "
        f"cap's [{view.cap.lower}, {view.cap.upper}] tasks per robot; raise max_deviation"
    )


def enumerate_all(view: UnitView, limit: int, limit_text: str) -> tuple[list[Members], int]:
    """Every combination of the tasks' options, vectorised (task 0 most significant, so the
    first best row is the robot-order tie-break). Returns the best and the count."""
    options = [view.options(i) for i in range(len(view.tasks))]
    count = math.prod(len(o) for o in options)
    if count > limit:
        raise TooLargeError(
            "tasks",
            f"brute_force would enumerate {count:,} plans (each task's eligible robots or "
            f"teams, multiplied), above its limit of {limit_text}; use 'dp' or 'optimal' "
            "for this size",
            code="too_large",
        )
    if count == 0:
        raise _no_completion(view)
    r, cap = view.n_robots, view.cap
    codes = np.arange(count, dtype=np.int64)
    values = np.zeros(count, dtype=np.int64)
    loads = np.tile(np.asarray(view.initial_loads, dtype=np.int64), (count, 1))
    stride = count
    digits = []
    for opts in options:
        stride //= len(opts)
        digit = (codes // stride) % len(opts)
        digits.append(digit)
        values += np.array([w for _, w in opts], dtype=np.int64)[digit]
        loads += np.array([view.increments(m) for m, _ in opts], dtype=np.int64)[digit]
    ok = ((loads >= cap.lower) & (loads <= cap.upper)).all(axis=1)
    if not ok.any():
        raise _no_completion(view)
    dev = np.abs(r * loads - cap.n_tasks).sum(axis=1)
    top = values[ok].max()
    tied = ok & (values == top)
    winner = int(np.flatnonzero(tied & (dev == dev[tied].min()))[0])
    return [opts[int(d[winner])][0] for opts, d in zip(options, digits, strict=True)], count


def dynamic_programme(view: UnitView, max_states: int) -> tuple[list[Members], int]:
    """Forward: load vectors from which the cap can still be met; backward: the best
    (weight, deviation) from each, the first best option kept. Returns choices and states."""
    cap, n = view.cap, len(view.tasks)
    bound = math.comb(sum(view.added) + view.n_robots, view.n_robots)
    if bound > max_states:
        raise TooLargeError(
            "tasks",
            f"dp would visit up to {bound:,} states for {sum(view.added)} task units and "
            f"{view.n_robots} robots, above its limit of {max_states:,}; use 'optimal' for "
            "this size",
            code="too_large",
        )
    options = [[(m, w, view.increments(m)) for m, w in view.options(i)] for i in range(n)]
    left = [sum(view.added[i:]) for i in range(n + 1)]
    start: Loads = view.initial_loads
    layers: list[set[Loads]] = [{start} if cap.can_complete(start, left[0]) else set()]
    for i in range(n):
        nxt: set[Loads] = set()
        for loads in layers[i]:
            for _, _, inc in options[i]:
                child = tuple(a + b for a, b in zip(loads, inc, strict=True))
                if cap.can_complete(child, left[i + 1]):
                    nxt.add(child)
        layers.append(nxt)
    value: dict[Loads, tuple[int, int]] = {
        loads: (0, deviation_units(loads, cap.n_tasks)) for loads in layers[n]
    }
    moves: list[dict[Loads, int]] = [{} for _ in range(n)]
    for i in range(n - 1, -1, -1):
        current: dict[Loads, tuple[int, int]] = {}
        for loads in layers[i]:
            best: tuple[int, int] | None = None
            for k, (_, w, inc) in enumerate(options[i]):
                child = tuple(a + b for a, b in zip(loads, inc, strict=True))
                if child not in value:
                    continue
                v, d = value[child]
                if best is None or better(v + w, d, *best):
                    best, moves[i][loads] = (v + w, d), k
            if best is not None:
                current[loads] = best
        value = current
    if start not in value:
        raise _no_completion(view)
    choices: list[Members] = []
    loads = start
    for i in range(n):
        members, _, inc = options[i][moves[i][loads]]
        choices.append(members)
        loads = tuple(a + b for a, b in zip(loads, inc, strict=True))
    return choices, sum(len(x) for x in layers)
