"""Typed links with lags (docs/schedules.md#links) in the list scheduler, the feasibility
check, the bounds and the exact CP-SAT model: each link type by hand, and CP-SAT's optimum
against an exhaustive search (tests/support/timed_checks.py: every assignment, every order per
robot, earliest starts by longest paths) on tiny instances with all four types, leads and
lags."""

from __future__ import annotations

import math
from typing import Any

import pytest
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st

from app.domain.errors import DomainError
from app.domain.links import Link
from app.domain.models import Instance
from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.dispatch import dispatch_schedule
from app.domain.scheduling.feasibility import Rule, check_schedule
from app.domain.scheduling.list_schedule import list_schedule, sequence_schedule
from app.domain.scheduling.progress import TimedProgress
from app.domain.scheduling.reported import retime
from app.domain.scheduling.schedule import build_schedule
from app.domain.serialize import instance_from_dict, instance_to_dict
from app.solvers.cpsat.bounds import CRITICAL_PATH, bound_floors
from app.solvers.registry import get_solver
from tests.support.timed_checks import best_makespan
from tests.support.timed_support import robot, task

# Task 0 takes 10 minutes, task 1 takes 6; (link from 0 to 1, start of 1 on another robot).
BY_TYPE = [
    ("FS", 5, 15.0),  # starts 5 after 0 ends
    ("FS", -4, 6.0),  # a lead: 4 before 0 ends
    ("SS", 3, 3.0),  # starts 3 after 0 starts
    ("SS", -5, 0.0),  # may start 5 before 0 does: the plan's start binds
    ("FF", 2, 6.0),  # ends 2 after 0 ends: 12 - 6
    ("FF", -8, 0.0),  # ends 8 before 0 ends: 2 - 6 < 0, the plan's start binds
    ("SF", 8, 2.0),  # ends 8 after 0 starts: 8 - 6
    ("SF", 20, 14.0),
]


def bound_of(kind: str, lag: float) -> float:
    """The start of task 1 its link alone allows, task 0 running [0, 10] and 1 taking 6."""
    return {"FS": 10 + lag, "SS": lag, "FF": 10 + lag - 6, "SF": lag - 6}[kind]


def pair(kind: str, lag: float, **first: Any) -> Problem:
    inst = Instance(
        tasks=(
            task(0, duration=10, **first),
            task(1, duration=6, after=(Link(0, kind, lag),)),
        ),
        robots=(robot("r"), robot("s")),
    )
    return Problem.build(inst, Mode.SUCCESS_FOCUSED)


@pytest.mark.parametrize(("kind", "lag", "start"), BY_TYPE)
def test_the_list_scheduler_starts_each_link_type_at_its_earliest(
    kind: str, lag: float, start: float
) -> None:
    problem = pair(kind, lag)
    schedule = list_schedule(problem, [0, 1])
    assert [(s.start, s.end) for s in schedule.slots] == [(0, 10), (start, start + 6)]
    assert check_schedule(problem, schedule) == []
    # Released at 30, the first task moves the second by its link.
    later = pair(kind, lag, release=30)
    moved = list_schedule(later, [0, 1])
    assert moved.slots[1].start == max(0.0, bound_of(kind, lag) + 30)
    # The same robot: appended after the first, whatever the link allows.
    same = list_schedule(problem, [0, 0])
    assert same.slots[1].start == max(10.0, start)
    assert check_schedule(problem, same) == []
    # Dispatch and fixed orders time it the same way.
    assert dispatch_schedule(problem, [0, 1], {(0, 0): 1, (1, 1): 1}).slots[1].start == start
    assert sequence_schedule(problem, [[0], [1]]).slots[1].start == start


@pytest.mark.parametrize(("kind", "lag", "start"), BY_TYPE)
def test_the_check_holds_each_link_to_the_minute(kind: str, lag: float, start: float) -> None:
    problem = pair(kind, lag)
    # A plan may start it later than the list scheduler would; exactly at the link's own
    # bound it holds, a minute earlier it breaks (unless the plan's start was binding).
    bound = bound_of(kind, lag)
    exact = build_schedule(problem, [0, 1], [0.0 + 20, bound + 20], None)
    assert check_schedule(problem, exact) == []
    early = build_schedule(problem, [0, 1], [20.0, bound + 19], None)
    (violation,) = check_schedule(problem, early)
    assert violation.rule is Rule.PRECEDENCE and violation.task == 1
    point = "starts" if kind[1] == "S" else "ends"
    assert f"task 1 (t1) {point} at" in violation.message
    if (kind, lag) != ("FS", 0):
        assert f"{kind} link, lag {lag:+g} min from task 0 (t0)" in violation.message


def test_a_plain_id_and_an_fs_link_with_no_lag_plan_the_same() -> None:
    def plan(after: tuple[Any, ...]) -> list[tuple[float, float]]:
        inst = Instance(
            tasks=(task(0, duration=10), task(1, duration=6, after=after)),
            robots=(robot("r"), robot("s")),
        )
        return [
            (s.start, s.end)
            for s in list_schedule(Problem.build(inst, Mode.BALANCED), [0, 1]).slots
        ]

    assert plan((0,)) == plan((Link(0),)) == plan((Link(0, "FS", 0),)) == [(0, 10), (10, 16)]


def test_links_survive_the_stored_form_and_plain_ids_stay_plain() -> None:
    inst = Instance(
        tasks=(
            task("a", duration=10),
            task("b", duration=6, after=("a",)),
            task("c", duration=4, after=(Link("a", "SS", -2.5), Link("b", "FF", 0))),
        ),
        robots=(robot("r"),),
    )
    data = instance_to_dict(inst)
    assert data["tasks"][1]["after"] == ["a"]
    assert data["tasks"][2]["after"] == [
        {"task": "a", "type": "SS", "lag": -2.5},
        {"task": "b", "type": "FF", "lag": 0},
    ]
    assert instance_from_dict(data) == inst


def test_the_critical_path_bound_counts_lags_and_types() -> None:
    # 0 (10) -SS+3-> 1 (6) -FF+4-> 2 (5): 1 ends at 9 at the earliest, 2 at 13; 0 ends at 10.
    inst = Instance(
        tasks=(
            task(0, duration=10),
            task(1, duration=6, after=(Link(0, "SS", 3),)),
            task(2, duration=5, after=(Link(1, "FF", 4), Link(0, "FS", 1))),
        ),
        robots=(robot("r"), robot("s"), robot("u")),
    )
    problem = Problem.build(inst, Mode.SUCCESS_FOCUSED)
    # 2 starts at 11 at the earliest (FS +1 after 0), ends 16; its FF bound (13) is weaker.
    assert bound_floors(problem)[CRITICAL_PATH] == 16
    solution = get_solver("schedule").solve(problem, options={"time_limit_s": 10})
    assert solution.details["schedule"].makespan == 16
    assert solution.details["status"] == "optimal"
    assert inst.timing.earliest == ((0.0, 3.0, 11.0), (10.0, 9.0, 16.0))


def test_a_deadline_a_link_makes_impossible_is_refused_naming_it() -> None:
    with pytest.raises(DomainError) as caught:
        Instance(
            tasks=(
                task(0, duration=10),
                task(1, duration=6, after=(Link(0, "FS", 30),), deadline=40),
            ),
            robots=(robot("r"),),
        )
    assert caught.value.field == "tasks.1.deadline" and caught.value.code == "impossible_deadline"
    # An FF link leaves the task its longest duration before that end.
    Instance(
        tasks=(
            task(0, duration=10),
            task(1, duration={"r": 30, "s": 2}, after=(Link(0, "FF", 5),), deadline=15),
        ),
        robots=(robot("r"), robot("s")),
    )


KINDS = ("FS", "SS", "FF", "SF")


@st.composite
def bodies(draw: st.DrawFn) -> dict[str, Any]:
    """A tiny timed /allocate body: 2-3 robots, 2-5 tasks, each linked to up to two earlier
    tasks with any type and a lag or a lead; per-robot durations, zones, releases, deadlines."""
    n_robots = draw(st.integers(2, 3))
    n_tasks = draw(st.integers(2, 4 if n_robots == 3 else 5))
    names = [f"r{i}" for i in range(n_robots)]
    robots = [
        {
            "name": name,
            "success": {"x": draw(st.integers(1, 20)) * 5 / 100},
            "zone": draw(st.sampled_from(["A", "B"])),
        }
        for name in names
    ]
    tasks = []
    for t in range(n_tasks):
        earlier = draw(st.lists(st.integers(0, t - 1), unique=True, max_size=2)) if t else []
        after = [
            {"task": p, "type": draw(st.sampled_from(KINDS)), "lag": draw(st.integers(-6, 8))}
            for p in earlier
        ]
        able = draw(st.lists(st.sampled_from(names), min_size=1, max_size=n_robots, unique=True))
        tasks.append(
            {
                "id": t,
                "features": ["x"],
                "duration": {n: draw(st.integers(1, 9)) for n in able},
                "after": after,
                "zone": draw(st.sampled_from(["A", "B"])),
                **({"release": r} if (r := draw(st.integers(0, 6))) else {}),
                **(
                    {"deadline": d}
                    if (d := draw(st.one_of(st.none(), st.integers(12, 40))))
                    else {}
                ),
            }
        )
    return {"tasks": tasks, "robots": robots, "travel": {"A": {"B": draw(st.integers(0, 4))}}}


@settings(
    max_examples=30,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(bodies(), st.booleans())
def test_cp_sat_matches_the_exhaustive_search_with_typed_links(
    body: dict[str, Any], makespan_only: bool
) -> None:
    note(repr(body))
    success = [[r["success"]["x"] for r in body["robots"]] for _ in body["tasks"]]
    es, span = best_makespan(body, success, None, success_first=not makespan_only)
    try:
        inst = instance_from_dict(
            {**body, "tasks": [{"name": str(t["id"]), **t} for t in body["tasks"]]}
        )
    except DomainError as refused:
        # The instance's own checks refuse only what no schedule can meet.
        assert refused.code in ("impossible_deadline", "no_shift_fits"), refused.message
        assert span == math.inf
        return
    kind = ObjectiveKind.MAKESPAN if makespan_only else ObjectiveKind.SUCCESS_THEN_MAKESPAN
    problem = Problem.build(inst, Mode.SUCCESS_FOCUSED, objective=Objective(kind, 0.0))
    solver = get_solver("schedule")
    if span == math.inf:
        with pytest.raises(DomainError) as err:
            solver.solve(problem, options={"time_limit_s": 20})
        assert err.value.code == "no_schedule", err.value.message
        return
    solution = solver.solve(problem, options={"time_limit_s": 20})
    schedule = solution.details["schedule"]
    assert check_schedule(problem, schedule) == []
    assert solution.details["status"] == "optimal"
    assert schedule.makespan == pytest.approx(span)
    assert solution.details["bound"] <= schedule.makespan + 1e-6
    if not makespan_only:
        got = sum(success[t][r] for t, r in enumerate(solution.assignment)) / inst.n_tasks
        assert got == pytest.approx(es)
    # The list scheduler's plan of the same assignment keeps every link too.
    listed = list_schedule(problem, solution.assignment)
    assert not [v for v in check_schedule(problem, listed) if v.rule is Rule.PRECEDENCE]
    assert listed.makespan >= bound_floors(problem)[CRITICAL_PATH] - 1e-6


def test_a_lead_lets_a_robot_do_the_successor_first_and_fixed_orders_keep_it() -> None:
    # 0 released at 1 (1 min); 1 (1 min) may start 2 min before 0 ends (FS -2): one robot
    # does 1 at 0 and 0 at 1, a makespan of 2; the list scheduler puts 1 in the idle
    # minute its robot left before 0 (appending it after 0 would end at 3).
    inst = Instance(
        tasks=(task(0, duration=1, release=1), task(1, duration=1, after=(Link(0, "FS", -2),))),
        robots=(robot("r"),),
    )
    problem = Problem.build(inst, Mode.SUCCESS_FOCUSED)
    listed = list_schedule(problem, [0, 0])
    assert [(s.start, s.end) for s in listed.slots] == [(1, 2), (0, 1)]
    assert check_schedule(problem, listed) == []
    ordered = sequence_schedule(problem, [[1, 0]])
    assert [(s.start, s.end) for s in ordered.slots] == [(1, 2), (0, 1)]
    assert check_schedule(problem, ordered) == []
    solution = get_solver("schedule").solve(problem, options={"time_limit_s": 10})
    assert solution.details["schedule"].makespan == 2
    # The critical path stops where the lead turns it back, and the reported view keeps
    # the robot's order.
    assert ordered.critical_path
    again = retime(problem, ordered, {})
    assert [(s.start, s.end) for s in again.slots] == [(1, 2), (0, 1)]
    assert check_schedule(problem, again) == []


def test_ss_and_ff_leads_let_the_graphs_plan_start_a_successor_before_its_predecessor() -> None:
    # The pour (20 min) waits for its release at 30; screeding (10) may start 15 min before
    # the pour starts (SS -15) and goes in the idle time before it on the same robot;
    # trowelling (10) must end no earlier than 5 min before the pour ends (FF -5), so it
    # cannot fit the 5 minutes left there and follows the pour. Travel both ways counts.
    inst = Instance(
        tasks=(
            task(0, duration=20, release=30),
            task(1, duration=10, after=(Link(0, "SS", -15),)),
            task(2, duration=10, after=(Link(0, "FF", -5),)),
        ),
        robots=(robot("r"),),
    )
    problem = Problem.build(inst, Mode.SUCCESS_FOCUSED)
    progress = TimedProgress(problem)
    while (t := progress.current()) < 3:
        (option,) = progress.options(t)
        placed = progress.place(t, 0)
        assert (placed.start, placed.end) == (option.start, option.end)
    assert {t: (p.start, p.end) for t, p in progress.placed.items()} == {
        0: (30, 50),
        1: (15, 25),
        2: (50, 60),
    }
    # The option says where the robot comes from: idle since minute 0, not after the pour.
    again = TimedProgress(problem)
    again.place(again.current(), 0)
    (screed,) = again.options(again.current())
    assert (screed.free, screed.start) == (0, 15)
    listed = list_schedule(problem, [0, 0, 0])
    assert [(s.start, s.end) for s in listed.slots] == [(30, 50), (15, 25), (50, 60)]
    assert check_schedule(problem, listed) == []


def test_a_lead_into_idle_time_keeps_the_travel_on_to_the_next_task() -> None:
    # As above with zones: screeding in zone B must travel back to the pour's zone A
    # (5 min each way), so its 10 minutes fit only if they end by minute 25.
    inst = Instance(
        tasks=(
            task(0, duration=20, release=30, zone="A"),
            task(1, duration=10, zone="B", after=(Link(0, "SS", -15),)),
        ),
        robots=(robot("r", zone="A"),),
        travel={"A": {"B": 5}},
    )
    problem = Problem.build(inst, Mode.SUCCESS_FOCUSED)
    listed = list_schedule(problem, [0, 0])
    assert [(s.start, s.end) for s in listed.slots] == [(30, 50), (15, 25)]
    assert check_schedule(problem, listed) == []
    tight = Instance(
        tasks=(inst.tasks[0], task(1, duration=12, zone="B", after=(Link(0, "SS", -15),))),
        robots=inst.robots,
        travel=inst.travel,
    )
    problem = Problem.build(tight, Mode.SUCCESS_FOCUSED)
    listed = list_schedule(problem, [0, 0])
    assert [(s.start, s.end) for s in listed.slots] == [(30, 50), (55, 67)]
    assert check_schedule(problem, listed) == []


@st.composite
def lead_bodies(draw: st.DrawFn) -> dict[str, Any]:
    """Sites where leads meet idle time: late releases and links that let a successor start
    well before its predecessor (one drawn example in eight puts a task into idle time
    its robot left behind, measured when this was written)."""
    names = [f"r{i}" for i in range(draw(st.integers(1, 2)))]
    tasks = []
    for t in range(draw(st.integers(2, 6))):
        earlier = draw(st.lists(st.integers(0, t - 1), unique=True, max_size=2)) if t else []
        tasks.append(
            {
                "id": t,
                "name": str(t),
                "features": ["x"],
                "duration": {n: draw(st.integers(1, 9)) for n in names},
                "after": [
                    {
                        "task": p,
                        "type": draw(st.sampled_from(KINDS)),
                        "lag": draw(st.integers(-15, 4)),
                    }
                    for p in earlier
                ],
                "zone": draw(st.sampled_from(["A", "B"])),
                "release": draw(st.integers(0, 30)),
            }
        )
    robots = [{"name": n, "success": {"x": 0.9}, "zone": "A"} for n in names]
    return {"tasks": tasks, "robots": robots, "travel": {"A": {"B": draw(st.integers(0, 4))}}}


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(bodies(), lead_bodies()), st.randoms(use_true_random=False))
def test_idle_time_taken_by_a_lead_breaks_no_rule(body: dict[str, Any], rng: Any) -> None:
    # Any assignment, every link type with leads, zones and releases: the list scheduler and
    # the graph's time lines (placing each task on a random able robot) break only what an
    # append-or-insert plan of a given assignment may (deadlines), never a link, an overlap
    # or the travel between two tasks.
    note(repr(body))
    try:
        inst = instance_from_dict(
            {**body, "tasks": [{"name": str(t["id"]), **t} for t in body["tasks"]]}
        )
    except DomainError:
        return
    problem = Problem.build(inst, Mode.SUCCESS_FOCUSED)
    tm = inst.timing
    progress = TimedProgress(problem)
    while (t := progress.current()) < tm.n_tasks:
        progress.place(t, rng.choice(tm.eligible_robots(t)))
    assignment = [progress.placed[t].robot for t in range(tm.n_tasks)]
    starts = [progress.placed[t].start for t in range(tm.n_tasks)]
    ends = [progress.placed[t].end for t in range(tm.n_tasks)]
    allowed = {Rule.DEADLINE, Rule.SHIFT}
    for plan in (
        build_schedule(problem, assignment, starts, ends),
        list_schedule(problem, assignment),
    ):
        assert [v for v in check_schedule(problem, plan) if v.rule not in allowed] == []
