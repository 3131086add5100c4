"""The true facts of the current decision, derived from the problem and the graph state."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

from app.domain.decision import DecisionContext, TeamFacts
from app.domain.links import explain
from app.domain.modes import strategic_weights
from app.domain.phases import Phase
from app.domain.problem import Problem
from app.domain.scheduling.progress import TimeOption
from app.domain.team_choice import best_and_fewest
from app.domain.teams import covers

# robot -> feature -> (basis, reports): app.domain.estimates.rate_notes
RateNotes = Mapping[str, Mapping[str, tuple[str, int]]]


def _rate_note(notes: Mapping[str, tuple[str, int]], features: tuple[str, ...]) -> str:
    parts = []
    for feature in features:
        if feature in notes:
            basis, reports = notes[feature]
            parts.append(
                f"{feature} configured, no reports yet"
                if basis == "prior"
                else f"{feature} {basis} on {reports} reports"
            )
    return "; ".join(parts)


def team_facts(
    problem: Problem, t: int, loads: tuple[int, ...], feasible: tuple[int, ...], guided: Any
) -> TeamFacts | None:
    """The team side of task t's decision (docs/allocation.md#teams); None for one robot.
    Untimed only: a timed team decision would add "members free in time" to `check`."""
    inst = problem.instance
    units = inst.units[t]
    if not units:
        return None
    allowed = set(feasible)
    rates = tuple(
        tuple(
            r_.success[f] if r in allowed and covers(r_, f) else None
            for r, r_ in enumerate(inst.robots)
        )
        for f in dict.fromkeys(units)
    )

    def check(members: tuple[int, ...]) -> str | None:
        # The seam for timed teams: validation, the candidate teams and the fallback all ask
        # this one question, so "every member free in time (and the deadline met)" is added
        # here, from the time model, once timed team tasks are scheduled.
        return problem.team_problem(t, loads, members)

    facts = TeamFacts(
        units=units,
        rates=rates,
        guided=tuple(guided) if guided is not None else None,
        check=check,
    )
    best, fewest = best_and_fewest(facts, loads, feasible, check)
    return replace(facts, best=best, fewest=fewest)


def decision_context(
    problem: Problem,
    state: Mapping[str, Any],
    *,
    tier: int = 0,
    rate_notes: RateNotes | None = None,
    timing: Sequence[TimeOption] = (),
    allocated: int | None = None,
) -> DecisionContext:
    """`timing`: on a timed instance, what each robot would make of the task in time
    (app.graph.timing); robots that would miss its deadline or break their shift are then
    not allowed, unless no allowed robot meets them."""
    inst, cap = problem.instance, problem.cap
    t = state["task_index"]
    loads = tuple(state["loads"])
    task = inst.tasks[t]
    view = state["view"]
    phase = Phase(view["phase"])
    bounds = None if cap.max_deviation is None else (cap.lower, cap.upper)
    feasible = tuple(view["feasible"])
    in_time = tuple(r for r in feasible if timing and timing[r].allowed)
    zone: str | None = None
    release = 0.0
    deadline: float | None = None
    links: tuple[str, ...] = ()
    if timing:
        tm = inst.timing
        zone_index = tm.task_zone[t]
        zone = None if zone_index is None else tm.zones[zone_index]
        release = tm.release[t]
        deadline = None if math.isinf(tm.deadline[t]) else tm.deadline[t]
        if any(not a.plain for a in tm.links[t]):
            links = tuple(explain(a, repr(str(inst.tasks[a.pred].name))) for a in tm.links[t])
    return DecisionContext(
        task_index=t,
        total_tasks=inst.n_tasks,
        task_name=task.name,
        features=task.features,
        robot_names=tuple(r.name for r in inst.robots),
        robot_labels=tuple(r.display for r in inst.robots),
        success=tuple(float(x) for x in inst.success[t]),
        loads=loads,
        target=problem.target,
        feasible=in_time or feasible,
        phase=phase,
        mode=problem.mode,
        weights=strategic_weights(problem.mode, phase),
        tier=tier,
        guided_robot=view["guided_robot"],
        guided_costs=tuple(costs) if (costs := view.get("guided_costs")) is not None else None,
        task_type=task.type,
        load_bounds=bounds,
        attempt=state.get("attempt") or 1,
        rate_notes=tuple(_rate_note(rate_notes.get(r.name, {}), task.features) for r in inst.robots)
        if rate_notes
        else (),
        timing=tuple(timing),
        zone=zone,
        release=release,
        deadline=deadline,
        links=links,
        allocated=allocated,
        eligible=() if inst.eligible.all() else tuple(bool(x) for x in inst.eligible[t]),
        team=team_facts(problem, t, loads, feasible, view.get("guided_team")),
    )
