"""One task's variables, as the one-robot model (`model.py`) and the team model
(`team_model.py`) both make them: its start and end inside its release, deadline, pin and
the horizon, and per robot able a presence literal with an optional interval on the task's
start, held inside that robot's shift (docs/schedules.md#schedulers)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from ortools.sat.python import cp_model

from app.domain.problem import Problem
from app.domain.time_model import TimeModel
from app.solvers.cpsat.time_scale import TimeScale


class TaskHost(Protocol):
    """What a model holds that a task's variables are made from and added to."""

    tm: TimeModel
    model: cp_model.CpModel
    scale: TimeScale
    problem: Problem
    candidates: list[list[int]]
    horizon: int
    present: dict[tuple[int, int], cp_model.IntVar]


def serial_horizon(host: TaskHost) -> int:
    """No schedule worth having ends later: everything one after another, from the latest
    fixed time, with the longest travel before each task (before any shift's end clips it)."""
    tm, up, problem = host.tm, host.scale.up, host.problem
    longest_travel = max((m for row in tm.travel_minutes for m in row), default=0.0)
    anchor = max(
        [*tm.release, problem.not_before, *(a for a, _ in tm.shifts)]
        + [s + tm.duration(t, problem.pinned[t]) for t, s in problem.pinned_starts.items()]
    )
    # Each duration rounded on its own: rounding the sum instead lost up to a unit per
    # task, and with sub-unit durations proved a feasible instance infeasible.
    total = sum(max(up(tm.duration(t, r)) for r in host.candidates[t]) for t in range(tm.n_tasks))
    # A positive lag is a wait no robot fills (docs/schedules.md#links).
    lags = sum(up(a.lag) for arcs in tm.links for a in arcs if a.lag > 0)
    return max(0, up(anchor) + total + tm.n_tasks * up(longest_travel) + lags)


@dataclass
class TaskWindow:
    start: cp_model.IntVar
    end: cp_model.IntVar
    lits: list[cp_model.IntVar]  # a presence per robot able, in `candidates` order
    sizes: list[int]  # its duration on each, in the model's units


def add_task_window(
    host: TaskHost,
    t: int,
    intervals: list[list[cp_model.IntervalVar]],
    tasks_on: list[list[int]],
) -> TaskWindow:
    """Task t's start, end and presences; each presence's interval goes to its robot's
    `intervals` and the task to its `tasks_on`. A pinned task is fixed at its start and may
    end past the horizon, which then grows."""
    tm, m, up, down = host.tm, host.model, host.scale.up, host.scale.down
    fixed = host.problem.pinned_starts.get(t)
    if fixed is not None:
        lo = hi = round(fixed * host.scale.units_per_minute)
    else:
        lo, hi = max(up(tm.release[t]), up(host.problem.not_before)), host.horizon
    end_hi = host.horizon if not math.isfinite(tm.deadline[t]) else down(tm.deadline[t])
    if fixed is not None:
        end_hi = max(end_hi, hi + max(up(tm.duration(t, r)) for r in host.candidates[t]))
        host.horizon = max(host.horizon, end_hi)
    start = m.new_int_var(lo, max(lo, hi), f"s{t}")
    end = m.new_int_var(lo, max(lo, end_hi), f"e{t}")
    window = TaskWindow(start, end, [], [])
    for r in host.candidates[t]:
        d = up(tm.duration(t, r))
        lit = m.new_bool_var(f"x{t}_{r}")
        host.present[t, r] = lit
        window.lits.append(lit)
        window.sizes.append(d)
        intervals[r].append(m.new_optional_fixed_size_interval_var(start, d, lit, f"i{t}_{r}"))
        tasks_on[r].append(t)
        a, b = tm.shifts[r]
        if fixed is None and up(a) > lo:
            m.add(start >= up(a)).only_enforce_if(lit)
        if fixed is None and math.isfinite(b):
            m.add(end <= down(b)).only_enforce_if(lit)
    return window
