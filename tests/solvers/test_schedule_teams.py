"""Team tasks in time (docs/schedules.md#teams-in-time): `schedule` equals an exhaustive
search over teams and per-robot orders on tiny timed team instances, and every method's
answer passes the one feasibility check.

The search is written here from docs/allocation.md#teams and docs/schedules.md#the-model,
without the app's schedulers: every choice of robot per single task and of distinct robots
covering a team's units, within the cap; every order of each robot's tasks (a team task in
each member's); each timed at its earliest (a task starts once its predecessors have ended
and every member has finished its previous task and travelled, its release and shifts
allow). It keeps the best (ES, then makespan) or, for `makespan`, the shortest with ES at
least the floor.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import itertools
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from fractions import Fraction

import icalendar
import pytest
from hypothesis import HealthCheck, assume, given, note, settings
from hypothesis import strategies as st
from icalendar.parser import Contentlines, split_on_unescaped_comma

from app.domain.errors import DomainError
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import Rule, check_schedule
from app.domain.scheduling.list_schedule import list_schedule, sequence_schedule
from app.domain.scheduling.schedule import Schedule
from app.domain.teams import covers
from app.exchange.mspdi_write import write_mspdi
from app.schedule_views import gantt_svg, schedule_csv, schedule_ics
from app.solvers.cpsat.team_dispatch import team_dispatch
from app.solvers.registry import get_solver
from benchmarks.team_schedules import measure

ZONES = ("A", "B")
TEAMS = ({"h": 2}, {"h": 1, "c": 1}, {"c": 2})


@dataclass(frozen=True)
class Case:
    problem: Problem
    travel: int


@st.composite
def instances(draw: st.DrawFn, max_tasks: int = 4, twins: bool = False) -> tuple[Instance, int]:
    n_robots = draw(st.integers(2, 3))
    n_tasks = draw(st.integers(2, max_tasks))
    travel = draw(st.integers(0, 6))
    rate = st.integers(1, 20).map(lambda x: x * 5 / 100)
    robots = []
    for i in range(n_robots):
        skills = draw(st.one_of(st.none(), st.sampled_from([("h",), ("c",), ("h", "c")])))
        robots.append(
            Robot(
                name=f"r{i}",
                success={"h": draw(rate), "c": draw(rate)},
                zone=draw(st.sampled_from(ZONES)),
                available=draw(
                    st.one_of(st.none(), st.tuples(st.integers(0, 4), st.integers(40, 80)))
                ),
                skills=skills,
            )
        )
    if twins:  # robot 1 interchangeable with robot 0: the model breaks that symmetry
        robots[1] = dataclasses.replace(robots[0], name="r1")
    tasks = []
    for t in range(n_tasks):
        team = draw(st.one_of(st.none(), st.sampled_from(TEAMS)))
        earlier = list(range(t))
        tasks.append(
            Task(
                id=t,
                name=f"t{t}",
                features=tuple(team) if team else (draw(st.sampled_from(["h", "c"])),),
                team=team,
                duration=draw(st.integers(1, 9)),
                after=tuple(draw(st.lists(st.sampled_from(earlier), unique=True, max_size=1)))
                if earlier
                else (),
                zone=draw(st.sampled_from(ZONES)),
                release=draw(st.one_of(st.none(), st.integers(0, 8))),
                deadline=draw(st.one_of(st.none(), st.integers(15, 50))),
            )
        )
    assume(any(task.team for task in tasks))
    try:
        return Instance(
            tasks=tuple(tasks), robots=tuple(robots), travel={"A": {"B": travel}}
        ), travel
    except DomainError:
        assume(False)
        raise


@st.composite
def cases(draw: st.DrawFn, twins: bool = False) -> Case:
    instance, travel = draw(instances(twins=twins))
    capped = draw(st.booleans())
    kind = draw(st.sampled_from(list(ObjectiveKind)))
    floor = draw(st.sampled_from([0.0, 0.4, 0.6])) if kind is ObjectiveKind.MAKESPAN else 0.0
    try:
        problem = Problem.build(
            instance,
            Mode.BALANCED if capped else Mode.SUCCESS_FOCUSED,
            1 if capped else None,
            objective=Objective(kind, floor),
        )
    except DomainError:
        assume(False)
        raise
    return Case(problem, travel)


def choices(inst: Instance, t: int) -> list[tuple[int, ...]]:
    """Every robot per unit (a team: distinct robots able to cover their units)."""
    task = inst.tasks[t]
    if task.team is None:
        return [(r,) for r in range(inst.n_robots) if inst.eligible[t, r]]
    units = inst.units[t]
    return [
        members
        for members in itertools.permutations(range(inst.n_robots), len(units))
        if all(covers(inst.robots[r], f) for r, f in zip(members, units, strict=True))
    ]


def success(inst: Instance, t: int, members: tuple[int, ...]) -> Fraction:
    task = inst.tasks[t]
    if task.team is None:
        rates = [
            Fraction(inst.robots[members[0]].success[f]).limit_denominator(100)
            for f in task.features
        ]
    else:
        rates = [
            Fraction(inst.robots[r].success[f]).limit_denominator(100)
            for r, f in zip(members, inst.units[t], strict=True)
        ]
    return sum(rates, Fraction(0)) / len(rates)


def minutes(inst: Instance, t: int) -> float:
    duration = inst.tasks[t].duration
    assert isinstance(duration, int | float)  # every task here has one number
    return float(duration)


def earliest(
    case: Case, members: list[tuple[int, ...]], orders: list[tuple[int, ...]]
) -> list[float] | None:
    """Earliest starts for these per-robot orders, or None if they cannot be kept."""
    inst = case.problem.instance
    n = inst.n_tasks
    start: list[float | None] = [None] * n
    position = [0] * len(orders)
    free = [float(r.available[0]) if r.available else 0.0 for r in inst.robots]
    where = [r.zone for r in inst.robots]
    for _ in range(n):
        for t in range(n):
            task = inst.tasks[t]
            if start[t] is not None:
                continue
            if any(
                position[r] == len(orders[r]) or orders[r][position[r]] != t for r in members[t]
            ):
                continue
            preds = [k for k, other in enumerate(inst.tasks) if other.id in task.after]
            if any(start[p] is None for p in preds):
                continue
            d = minutes(inst, t)
            ready = [free[r] + (0 if where[r] == task.zone else case.travel) for r in members[t]]
            ends = [(start[p] or 0.0) + minutes(inst, p) for p in preds]
            s = max([*ready, float(task.release or 0), *ends])
            if task.deadline is not None and s + d > task.deadline:
                return None
            for r in members[t]:
                shift = inst.robots[r].available
                if shift is not None and s + d > shift[1]:
                    return None
                free[r], where[r] = s + d, task.zone
                position[r] += 1
            start[t] = s
            break
    if any(s is None for s in start):
        return None
    return [float(s) for s in start if s is not None]


def exhaustive(case: Case) -> tuple[Fraction, float] | None:
    problem, inst = case.problem, case.problem.instance
    floor = Fraction(problem.objective.min_expected_success).limit_denominator(100)
    best: tuple[Fraction, float] | None = None
    for members in itertools.product(*(choices(inst, t) for t in range(inst.n_tasks))):
        loads = [sum(r in m for m in members) for r in range(inst.n_robots)]
        if not problem.cap.respected_by(loads):
            continue
        es = sum((success(inst, t, m) for t, m in enumerate(members)), Fraction(0)) / inst.n_tasks
        if problem.objective.kind is ObjectiveKind.MAKESPAN and es < floor:
            continue
        mine = [[t for t, m in enumerate(members) if r in m] for r in range(inst.n_robots)]
        for orders in itertools.product(*(itertools.permutations(m) for m in mine)):
            starts = earliest(case, list(members), list(orders))
            if starts is None:
                continue
            makespan = max(s + minutes(inst, t) for t, s in enumerate(starts))
            if best is None:
                best = (es, makespan)
            elif problem.objective.kind is ObjectiveKind.SUCCESS_THEN_MAKESPAN:
                best = max(best, (es, makespan), key=lambda b: (b[0], -b[1]))
            elif makespan < best[1]:
                best = (es, makespan)
    return best


def plan_success(
    inst: Instance, assignment: list[int], teams: dict[int, tuple[int, ...]]
) -> Fraction:
    total = sum(
        (success(inst, t, teams.get(t) or (r,)) for t, r in enumerate(assignment)), Fraction(0)
    )
    return total / inst.n_tasks


@settings(
    max_examples=30,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(cases())
def test_schedule_matches_an_exhaustive_search_over_teams_and_orders(case: Case) -> None:
    _matches_the_exhaustive_search(case)


@settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(cases(twins=True))
def test_schedule_with_interchangeable_robots_matches_an_exhaustive_search(case: Case) -> None:
    # The symmetry the team model breaks among twins (team_model._break_symmetry) must
    # keep an optimum: the exhaustive search here breaks nothing.
    _matches_the_exhaustive_search(case)


def _matches_the_exhaustive_search(case: Case) -> None:
    p = case.problem
    note(f"{p.instance}\n{p.mode} {p.cap} {p.objective}")
    expected = exhaustive(case)
    solver = get_solver("schedule")
    if expected is None:
        with pytest.raises(DomainError) as err:
            solver.solve(p, options={"time_limit_s": 20})
        assert err.value.code in ("no_schedule", "infeasible_cap"), err.value.message
        return
    solution = solver.solve(p, options={"time_limit_s": 20})
    details = solution.details
    schedule = details["schedule"]
    assert check_schedule(p, schedule) == []
    assert details["status"] == "optimal", details["stages"]  # never a false "optimal" either
    assert schedule.makespan == pytest.approx(expected[1])
    assert solution.teams == schedule.teams
    es = plan_success(p.instance, solution.assignment, solution.teams)
    if p.objective.kind is ObjectiveKind.SUCCESS_THEN_MAKESPAN:
        assert es == expected[0]
    else:
        assert es >= Fraction(p.objective.min_expected_success).limit_denominator(100)


# The list scheduler waits where it must and never breaks these; a given assignment may
# still end a task past a deadline or a shift (docs/schedules.md#schedulers: nothing hidden).
KEPT = {Rule.DEADLINE, Rule.SHIFT}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(instances(max_tasks=7), st.sampled_from(["optimal", "greedy", "dp"]))
def test_every_team_method_gets_a_schedule_that_keeps_the_rules(
    drawn: tuple[Instance, int], method: str
) -> None:
    instance, _ = drawn
    problem = Problem.build(instance, Mode.SUCCESS_FOCUSED)
    solution = get_solver(method).solve(problem)
    schedule = solution.details["schedule"]
    assert schedule is not None and schedule.teams == solution.teams
    broken = check_schedule(problem, schedule)
    assert {v.rule for v in broken} <= KEPT, broken
    no_limits = all(t.deadline is None for t in instance.tasks) and all(
        r.available is None for r in instance.robots
    )
    assert not broken or not no_limits
    # every member of a team works over the same times, in its own lane
    lanes = schedule.sequences(instance.n_robots)
    for t, members in solution.teams.items():
        assert all(t in lanes[r] for r in members)
        assert sum(t in lane for lane in lanes) == len(members)
    # re-timing its own per-robot orders gives the same times (the schedule is tight)
    again = sequence_schedule(problem, lanes, schedule.teams)
    assert [s.start for s in again.slots] == pytest.approx([s.start for s in schedule.slots])


def test_a_team_task_starts_when_its_last_member_arrives() -> None:
    tasks = (
        Task(id="a", name="carry", features=("h",), duration=10, zone="A"),
        Task(id="b", name="lift", features=("h",), team={"h": 2}, duration=5, zone="B"),
    )
    robots = (
        Robot(name="near", success={"h": 0.9}, zone="B"),
        Robot(name="far", success={"h": 0.8}, zone="A"),
    )
    problem = Problem.build(
        Instance(tasks=tasks, robots=robots, travel={"A": {"B": 7}}), Mode.SUCCESS_FOCUSED
    )
    schedule = list_schedule(problem, [1, 0], {1: (0, 1)})
    lift = schedule.slots[1]
    # 'far' carries until 10, then travels 7: the lift waits for it, 'near' idles
    assert (lift.start, lift.end) == (17.0, 22.0)
    assert lift.members == (0, 1) and lift.travel_of(1) == 7.0 and lift.travel_of(0) == 0.0
    assert check_schedule(problem, schedule) == []
    assert [s.kind.value for s in schedule.critical_path] == ["task", "travel", "task"]
    assert schedule.robot_time[0].busy == 5.0 and schedule.robot_time[1].busy == 15.0
    # a member in two places at once, or a unit without its robot, is caught
    clash = list_schedule(problem, [1, 0], {1: (0, 1)})
    moved = sequence_schedule(problem, [[1], [1, 0]], {1: (0, 1)})
    assert moved.slots[0].start >= moved.slots[1].end
    overlap = type(clash)(
        slots=(clash.slots[0], type(lift)(**{**lift.__dict__, "start": 3.0, "end": 8.0})),
        makespan=clash.makespan,
        robot_time=clash.robot_time,
        critical_path=clash.critical_path,
        start=None,
    )
    rules = {v.rule for v in check_schedule(problem, overlap)}
    assert Rule.OVERLAP in rules or Rule.TRAVEL in rules
    lone = type(clash)(
        slots=(clash.slots[0], type(lift)(**{**lift.__dict__, "team": (0, 0)})),
        makespan=clash.makespan,
        robot_time=clash.robot_time,
        critical_path=clash.critical_path,
        start=None,
    )
    assert Rule.TEAM in {v.rule for v in check_schedule(problem, lone)}


def _team_plan() -> tuple[Problem, Schedule]:
    tasks = (
        Task(id="beam", name="Lift, beam", features=("h",), team={"h": 2}, duration=30, zone="A"),
        Task(
            id="panel",
            name="Fix panel",
            features=("h", "c"),
            team={"h": 1, "c": 1},
            duration=20,
            zone="B",
            after=("beam",),
        ),
        Task(id="sweep", name="Sweep", features=("c",), duration=15, zone="B"),
    )
    robots = (
        Robot(name="crane", success={"h": 0.9, "c": 0.2}, zone="A", skills=("h",)),
        Robot(name="arm;1,b", success={"h": 0.3, "c": 0.95}, zone="B"),
        Robot(name="lifter", success={"h": 0.8, "c": 0.4}, zone="A"),
    )
    start = datetime(2026, 12, 7, 7, 0, tzinfo=UTC)
    instance = Instance(tasks=tasks, robots=robots, travel={"A": {"B": 6}}, start=start)
    problem = Problem.build(instance, Mode.SUCCESS_FOCUSED)
    solution = get_solver("optimal").solve(problem)
    return problem, solution.details["schedule"]


def test_csv_has_one_row_per_task_and_member() -> None:
    problem, schedule = _team_plan()
    rows = list(csv.DictReader(io.StringIO(schedule_csv(problem, schedule))))
    expected = [
        (problem.instance.tasks[s.task].id, problem.instance.robots[m].name)
        for s in schedule.slots
        for m in s.members
    ]
    assert [(r["task_id"], r["robot"]) for r in rows] == expected
    assert len(rows) == 2 + 2 + 1
    for row in rows:
        slot = next(
            s for s in schedule.slots if problem.instance.tasks[s.task].id == row["task_id"]
        )
        robot = problem.instance.robot_index(row["robot"])
        assert robot is not None
        assert (float(row["start_min"]), float(row["end_min"])) == (slot.start, slot.end)
        assert float(row["travel_min"]) == slot.travel_of(robot)
        if slot.team:
            unit = slot.team.index(robot)
            assert row["feature"] == problem.instance.units[slot.task][unit]
        else:
            assert row["feature"] == ""


def test_ics_has_one_event_per_task_with_every_member_in_resources() -> None:
    problem, schedule = _team_plan()
    data = schedule_ics(problem, schedule, calendar_name="Site", uid_prefix="p")
    events = list(icalendar.Calendar.from_ical(data).walk("VEVENT"))
    assert len(events) == problem.instance.n_tasks
    # RFC 5545 3.8.1.10: RESOURCES is a list of TEXT values separated by commas. The
    # Calendar reads it as one TEXT, so the raw values come from icalendar's line parser
    # (unfolded) and its own split on unescaped commas.
    raw = [
        line.split(":", 1)[1]  # as written: parts() would unescape the separators too
        for line in Contentlines.from_ical(data.decode())
        if line.startswith("RESOURCES:")
    ]
    robots = problem.instance.robots
    for event, slot, value in zip(events, schedule.slots, raw, strict=True):
        names = split_on_unescaped_comma(value)
        assert sorted(names) == sorted(robots[m].name for m in slot.members)
        assert schedule.start is not None
        assert event.decoded("DTSTART") == schedule.start + timedelta(minutes=slot.start)


def test_gantt_links_a_teams_bars_across_lanes() -> None:
    problem, schedule = _team_plan()
    root = ET.fromstring(gantt_svg(problem, schedule))
    ns = "{http://www.w3.org/2000/svg}"
    bars = [e for e in root.iter(f"{ns}rect") if "team" in (e.get("class") or "").split()]
    links = [e for e in root.iter(f"{ns}line") if e.get("class") == "team-link"]
    for slot in schedule.slots:
        task_id = str(problem.instance.tasks[slot.task].id)
        mine = [b for b in bars if b.get("data-task") == task_id]
        assert len(mine) == (len(slot.team) if slot.team else 0)
        titles = {b.findtext(f"{ns}title") or "" for b in mine}
        assert len(titles) <= 1  # one shared title naming the whole team
        if slot.team:
            title = next(iter(titles))
            assert all(problem.instance.robots[m].name in title for m in slot.team)
            (link,) = [x for x in links if x.get("data-task") == task_id]
            assert float(link.get("y2") or 0) > float(link.get("y1") or 0)


def test_a_team_instance_past_the_team_models_size_is_refused_with_a_sentence() -> None:
    zones = ("A", "B", "C")
    tasks = tuple(
        Task(
            id=t,
            name=f"t{t}",
            features=("h",),
            team={"h": 2} if t % 10 == 0 else None,
            duration=5,
            zone=zones[t % 3],
        )
        for t in range(240)
    )
    robots = tuple(Robot(name=f"r{i}", success={"h": 0.8}, zone="A") for i in range(5))
    travel = {"A": {"B": 3, "C": 4}, "B": {"C": 2}}
    problem = Problem.build(
        Instance(tasks=tasks, robots=robots, travel=travel), Mode.SUCCESS_FOCUSED
    )
    with pytest.raises(DomainError) as err:
        get_solver("schedule").solve(problem)
    assert err.value.code == "too_large" and err.value.field == "tasks"
    assert "'optimal'" in err.value.message and "literals" in err.value.message
    # the list scheduler still times optimal's teams
    assert get_solver("optimal").solve(problem).details["schedule"] is not None


def test_mspdi_export_has_one_assignment_per_task_and_member() -> None:
    problem, schedule = _team_plan()
    root = ET.fromstring(write_mspdi(problem, schedule, project_name="team plan"))
    ns = "{http://schemas.microsoft.com/project}"
    uid_of = {t.findtext(f"{ns}Name"): t.findtext(f"{ns}UID") for t in root.iter(f"{ns}Task")}
    names = {r.findtext(f"{ns}UID"): r.findtext(f"{ns}Name") for r in root.iter(f"{ns}Resource")}
    held = sorted(
        (a.findtext(f"{ns}TaskUID"), names[a.findtext(f"{ns}ResourceUID")])
        for a in root.iter(f"{ns}Assignment")
    )
    tasks, robots = problem.instance.tasks, problem.instance.robots
    expected = sorted(
        (uid_of[tasks[s.task].name], robots[m].name) for s in schedule.slots for m in s.members
    )
    assert held == expected and len(held) == 5


def test_team_times_finer_than_the_models_unit_are_never_called_optimal() -> None:
    # Rounded up one by one at the model's scale: the plan is feasible, its bound the
    # chains' floor, and "optimal" is not claimed (docs/schedules.md#teams-in-time).
    tasks = tuple(
        Task(id=t, name=f"t{t}", features=("h",), team={"h": 2} if t % 2 else None, duration=0.0001)
        for t in range(6)
    )
    robots = tuple(Robot(name=f"r{i}", success={"h": 0.5 + i / 10}) for i in range(3))
    problem = Problem.build(Instance(tasks=tasks, robots=robots), Mode.SUCCESS_FOCUSED)
    details = get_solver("schedule").solve(problem).details
    assert details["status"] == "feasible"
    assert check_schedule(problem, details["schedule"]) == []
    assert 0 < details["bound"] <= details["objective_value"]
    assert details["bound_source"] == "precedence chains and work"


def test_the_team_benchmark_measures_a_method() -> None:
    row = measure(Mode.BALANCED, "optimal")
    assert row.method == "optimal" and row.broken == 0 and row.makespan > 0 and 0 < row.es <= 1


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(instances(max_tasks=7))
def test_the_team_dispatch_gives_orders_the_list_scheduler_times_within_the_rules(
    drawn: tuple[Instance, int],
) -> None:
    # The team model's second start (team_dispatch.py): orders and teams that
    # `sequence_schedule` accepts, covering every unit with distinct able robots; only a
    # deadline or a shift may break (the caller then drops the plan).
    instance, _ = drawn
    problem = Problem.build(instance, Mode.SUCCESS_FOCUSED)
    candidates = [list(instance.timing.eligible_robots(t)) for t in range(instance.n_tasks)]
    plan = team_dispatch(problem, candidates)
    assert plan is not None
    sequences, teams = plan
    schedule = sequence_schedule(problem, sequences, teams)
    assert {v.rule for v in check_schedule(problem, schedule)} <= KEPT
    assert set(teams) == {t for t, task in enumerate(instance.tasks) if task.team}
