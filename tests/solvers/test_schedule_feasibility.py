"""The one feasibility check (docs/schedules.md#a-schedule-and-its-check): each rule broken once,
and nothing else reported.

The site: zones A and B, 4 minutes apart. t0 (A, 5 min) -> t1 (B, 3 min, only robot r);
t2 (B, 4 min, released at 2, deadline 60). Robot r starts in A, shift [0, 100]; robot s
starts in B, shift [1, 50]. A feasible plan: r does t0 0-5, travels, t1 9-12; s does t2 2-6.
"""

from __future__ import annotations

import dataclasses
from datetime import UTC, datetime
from typing import Any

import pytest

from app.domain.models import Instance
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import Rule, check_schedule
from app.domain.scheduling.schedule import Schedule, StepKind, build_schedule
from tests.support.timed_support import robot, task

START = datetime(2026, 3, 2, 7, 0, tzinfo=UTC)


def site() -> Instance:
    return Instance(
        tasks=(
            task(0, duration=5, zone="A"),
            task(1, duration={"r": 3}, after=(0,), zone="B"),
            task(2, duration=4, zone="B", release=2, deadline=60),
        ),
        robots=(
            robot("r", zone="A", available=(0, 100)),
            robot("s", 0.5, zone="B", available=(1, 50)),
        ),
        travel={"A": {"B": 4}},
        start=START,
    )


def plan(problem: Problem, robots: list[int], starts: list[float], **kw: Any) -> Schedule:
    return build_schedule(problem, robots, starts, **kw)


FEASIBLE = ([0, 0, 1], [0.0, 9.0, 2.0])


def test_a_feasible_plan_breaks_nothing_and_reads_right() -> None:
    problem = Problem.build(site(), Mode.SUCCESS_FOCUSED)
    schedule = plan(problem, *FEASIBLE)
    assert check_schedule(problem, schedule) == []
    assert schedule.makespan == 12
    assert [(s.start, s.end, s.zone, s.travel) for s in schedule.slots] == [
        (0, 5, "A", 0),
        (9, 12, "B", 4),
        (2, 6, "B", 0),
    ]
    r, s = schedule.robot_time
    assert (r.busy, r.travel, r.idle) == (8, 4, 0)
    assert (s.busy, s.travel, s.idle) == (4, 0, 7)  # shift from 1 to the makespan 12
    path = [(step.kind, step.task, step.start, step.end) for step in schedule.critical_path]
    assert path == [
        (StepKind.TASK, 0, 0, 5),
        (StepKind.TRAVEL, 1, 5, 9),
        (StepKind.TASK, 1, 9, 12),
    ]
    assert schedule.wall_clock(9) == "2026-03-02T07:09:00+00:00"
    out = schedule.to_dict(problem)
    assert out["tasks"][1] == {
        "task_id": 1,
        "robot": "r",
        "start": 9.0,
        "end": 12.0,
        "start_at": "2026-03-02T07:09:00+00:00",
        "end_at": "2026-03-02T07:12:00+00:00",
        "zone": "B",
        "travel": 4.0,
    }
    assert out["robots"]["s"] == {"busy": 4.0, "idle": 7.0, "travel": 0.0}
    assert [c["kind"] for c in out["critical_path"]] == ["task", "travel", "task"]


def test_a_wait_for_a_release_is_on_the_critical_path() -> None:
    inst = Instance(tasks=(task(0, duration=5, release=30),), robots=(robot("r"),))
    problem = Problem.build(inst, Mode.SUCCESS_FOCUSED)
    schedule = plan(problem, [0], [30.0])
    assert [(s.kind, s.cause, s.start, s.end) for s in schedule.critical_path] == [
        (StepKind.WAIT, "release", 0, 30),
        (StepKind.TASK, "works", 30, 35),
    ]


CASES: dict[str, tuple[Rule, dict[str, Any], list[int], list[float], dict[str, Any]]] = {
    # name: (rule, Problem.build arguments, robots, starts, build_schedule extras)
    "ineligible robot": (Rule.ELIGIBILITY, {}, [0, 1, 1], [0, 12, 2], {"ends": [5, 15, 6]}),
    "wrong duration": (Rule.DURATION, {}, [0, 0, 1], [0, 9, 2], {"ends": [5, 12, 7]}),
    "starts before its predecessor ends": (Rule.PRECEDENCE, {}, [1, 0, 1], [5, 5, 14], {}),
    "two tasks at once": (Rule.OVERLAP, {}, [0, 0, 0], [0, 7, 3], {}),
    "no time to travel between tasks": (Rule.TRAVEL, {}, [0, 0, 1], [0, 7, 2], {}),
    "no time to travel from the start zone": (Rule.TRAVEL, {}, [1, 0, 1], [1, 9, 10], {}),
    "before its release": (Rule.RELEASE, {}, [0, 0, 1], [0, 9, 1], {}),
    "after its deadline": (Rule.DEADLINE, {}, [0, 0, 0], [0, 9, 57], {}),
    "outside the shift": (Rule.SHIFT, {}, [0, 0, 1], [0, 9, 47], {}),
    "before now": (Rule.NOT_BEFORE, {"not_before": 1}, [0, 0, 1], [0, 9, 2], {}),
    "pin moved": (Rule.PIN, {"pinned": {2: 0}}, [0, 0, 1], [0, 9, 2], {}),
    "pinned start moved": (
        Rule.PIN,
        {"pinned": {0: 0}, "pinned_starts": {0: 0.5}},
        [0, 0, 1],
        [0, 9, 2],
        {},
    ),
    "new task on an unavailable robot": (
        Rule.UNAVAILABLE,
        {"unavailable": [1]},
        [0, 0, 1],
        [0, 9, 2],
        {},
    ),
    "cap broken": (
        Rule.CAP,
        {"mode": Mode.BALANCED, "max_deviation": 0.5},
        [0, 0, 0],
        [0, 9, 12],
        {},
    ),
}


@pytest.mark.parametrize("name", list(CASES))
def test_each_rule_broken_once(name: str) -> None:
    rule, build, robots, starts, extra = CASES[name]
    args = {"mode": Mode.SUCCESS_FOCUSED, **build}
    problem = Problem.build(site(), **args)
    assert check_schedule(problem, plan(problem, *FEASIBLE)) == [] or build, "base plan"
    violations = check_schedule(problem, plan(problem, robots, [float(s) for s in starts], **extra))
    assert {v.rule for v in violations} == {rule}, [v.message for v in violations]
    assert all(v.message for v in violations)


def test_a_schedule_that_misses_a_task_is_incomplete() -> None:
    problem = Problem.build(site(), Mode.SUCCESS_FOCUSED)
    schedule = plan(problem, *FEASIBLE)
    short = dataclasses.replace(schedule, slots=schedule.slots[:2])
    assert [v.rule for v in check_schedule(problem, short)] == [Rule.COMPLETE]


def test_violations_name_the_task_and_the_robot() -> None:
    problem = Problem.build(site(), Mode.SUCCESS_FOCUSED)
    (v,) = check_schedule(problem, plan(problem, [0, 0, 0], [0, 9, 57]))
    assert (v.task, v.robot) == (2, 0)
    assert "task 2" in v.message and "deadline 60" in v.message
