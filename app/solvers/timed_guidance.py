"""Optimizer guidance on a timed instance (docs/schedules.md#guidance-in-time): the
`schedule` solver's plan, solved once when the run starts.

Who alone is not enough in time. The graph places each task when it decides it, at the
earliest its robot and predecessors allow, so the times depend on the order of the
decisions: the earliest-start order (docs/schedules.md#the-order-of-decisions) gives each robot the
plan's tasks in another sequence than the plan's, and the guided makespan fell 20-55% short of the
optimum on `baseline_timed`. So a guided run decides in the plan's order (by the plan's starts, ties
in queue order; only ready tasks come up, so precedence holds): a robot that follows the
plan gets the plan's tasks in the plan's sequence, each placed no later than the plan has
it (by induction over the order: its predecessors and the robot's previous task end no
later), and the makespan is the plan's. Unguided runs keep the earliest-start order.

One plan per run, never re-solved. Where the run departs from it (a reasoner overrules
the guidance, a review), the rest is still decided in the plan's order, which stays a valid
order (precedence-respecting; the times are placed as the graph chose), and the plan's
robot remains the advice. Re-planning would guide better after a departure but CP-SAT
stops at a wall-clock limit, so a re-plan is not reproducible; with one stored plan a run
resumed after a crash decides in the same order with the same advice
(docs/schedules.md, "Runs in time"). The plan itself is solved on a deterministic budget
(`GUIDANCE_TIME_LIMIT_S` of deterministic time, one worker, seed 0), so the same run plans
the same on a quiet and on a loaded machine; the event records that budget. The durable
runs store the plan as the run's `guidance_planned` event and read it back on resume
(app.runs.records).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from app.domain.decision import GuidedChoice
from app.domain.errors import DomainError
from app.domain.problem import Problem

GUIDANCE_TIME_LIMIT_S = 5.0
# The wall-clock safety net of the guidance plan, far above what its deterministic budget
# takes even on a loaded machine: a plan cut by the wall clock would depend on the load.
GUIDANCE_WALL_CAP_S = 300.0


@dataclass(frozen=True)
class GuidancePlan:
    """The `schedule` solver's plan a guided timed run follows: per task its robot and
    start. Empty: no schedule was found in time, so the run is not guided."""

    robots: tuple[int, ...]
    starts: tuple[float, ...]
    # docs/allocation.md#teams: a team task's members in unit order (the exact team schedule's),
    # by task index; empty without team tasks.
    teams: Mapping[int, tuple[int, ...]] = dataclasses.field(default_factory=dict)
    # How it was solved: the budget (`time_limit_s`, deterministic units, workers, seed,
    # whether the wall-clock cap cut it), the model, status and makespan. Empty: not known.
    budget: Mapping[str, Any] = dataclasses.field(default_factory=dict, compare=False)

    def as_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"robots": list(self.robots), "starts": list(self.starts)}
        if self.teams:  # only then: a plan without teams is stored as it always was
            out["teams"] = {str(t): list(m) for t, m in sorted(self.teams.items())}
        if self.budget:
            out["budget"] = dict(self.budget)
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> GuidancePlan:
        return cls(
            tuple(int(r) for r in data.get("robots") or ()),
            tuple(float(s) for s in data.get("starts") or ()),
            {int(t): tuple(int(r) for r in m) for t, m in (data.get("teams") or {}).items()},
            dict(data.get("budget") or {}),
        )


def plan_guidance(problem: Problem, *, time_limit_s: float = GUIDANCE_TIME_LIMIT_S) -> GuidancePlan:
    """The plan for a run that has decided nothing yet (its pins are the problem's)."""
    # Imported here: OR-Tools takes half a second to import, and every server start reads
    # this module (a resumed run reads its stored plan); only a guided timed run solves one.
    from app.solvers.cpsat.search import solve_schedule

    try:
        outcome = solve_schedule(
            problem, time_limit_s=time_limit_s, workers=1, seed=0, wall_cap_s=GUIDANCE_WALL_CAP_S
        )
    except DomainError:
        # No schedule exists (or none was found in time): no guidance, the graph decides
        # by its own rule and in the earliest-start order.
        return GuidancePlan((), ())
    slots = outcome.schedule.slots  # one per task, in queue order
    budget = {
        **outcome.budget,
        "model": outcome.model,
        "status": outcome.status,
        "makespan": outcome.makespan,
    }
    return GuidancePlan(
        tuple(s.robot for s in slots),
        tuple(float(s.start) for s in slots),
        {s.task: tuple(s.team) for s in slots if s.team},
        budget,
    )


def guided_problem(problem: Problem, plan: GuidancePlan) -> Problem:
    """The problem whose decision order is the plan's (unchanged without a plan)."""
    if not plan.robots:
        return problem
    return dataclasses.replace(problem, decide_by=MappingProxyType(dict(enumerate(plan.starts))))


class ScheduleGuidance:
    """The graph's guidance: the plan's robot for the task being decided; for a team task the
    plan's team (docs/allocation.md#teams), which the rules follow when it is still allowed
    (the cap, and its members free in time on the graph's own time lines)."""

    def __init__(self, plan: GuidancePlan) -> None:
        self._robots = plan.robots
        self._teams = plan.teams

    def __call__(self, task_index: int, loads: Sequence[int]) -> int | GuidedChoice | None:
        if task_index >= len(self._robots):
            return None
        team = self._teams.get(task_index)
        if team:
            return GuidedChoice(team[0], (), team)
        return self._robots[task_index]
