"""The true facts of the current decision, derived from the problem and the graph state."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

from app.domain.decision import DecisionContext, Members, TeamFacts
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


TeamTime = Callable[[Members], TimeOption]


def team_facts(
    problem: Problem,
    t: int,
    loads: tuple[int, ...],
    feasible: tuple[int, ...],
    guided: Any,
    *,
    timing: Sequence[TimeOption] = (),
    team_time: TeamTime | None = None,
    later: Sequence[int] | None = None,
) -> tuple[TeamFacts | None, tuple[int, ...]]:
    """The team side of task t's decision (docs/allocation.md#teams); None for one robot. With
    the robots that may join a team: on a timed instance those whose own earliest end meets the
    deadline and their shift (a team never starts before any member could), and a team must
    also be free in time as a whole (`team_time`), unless no team the cap allows is: then time
    rules out no one, as for one robot (docs/schedules.md#validation-in-time)."""
    units = problem.instance.units[t]
    if not units:
        return None, feasible
    in_time = tuple(r for r in feasible if timing and timing[r].allowed)
    if team_time is not None and in_time:
        facts = _team_facts(problem, t, loads, in_time, guided, later, team_time)
        if facts.best is not None:
            return facts, in_time
    return _team_facts(problem, t, loads, feasible, guided, later, None, team_time), feasible


def _team_facts(
    problem: Problem,
    t: int,
    loads: tuple[int, ...],
    feasible: tuple[int, ...],
    guided: Any,
    later: Sequence[int] | None,
    in_time: TeamTime | None,
    team_time: TeamTime | None = None,
) -> TeamFacts:
    inst = problem.instance
    units = inst.units[t]
    allowed = set(feasible)
    rates = tuple(
        tuple(
            r_.success[f] if r in allowed and covers(r_, f) else None
            for r, r_ in enumerate(inst.robots)
        )
        for f in dict.fromkeys(units)
    )

    def check(members: tuple[int, ...]) -> str | None:
        # Validation, the candidate teams and the fallback all ask this one question: the
        # cap for the tasks after this one, then (timed) "members free in time".
        why = problem.team_problem(t, loads, members, later)
        if why is None and in_time is not None:
            option = in_time(members)
            if not option.allowed:
                why = (
                    f"the team would start at minute {option.start:g} and end at "
                    f"{option.end:g}, which {option.why_not}"
                )
        return why

    facts = TeamFacts(
        units=units,
        rates=rates,
        guided=tuple(guided) if guided is not None else None,
        check=check,
        timing=in_time or team_time,
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
    team_time: TeamTime | None = None,
    later: Sequence[int] | None = None,
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
    team, team_allowed = team_facts(
        problem,
        t,
        loads,
        feasible,
        view.get("guided_team"),
        timing=timing,
        team_time=team_time,
        later=later,
    )
    if team is not None:
        in_time = team_allowed
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
        team=team,
    )
