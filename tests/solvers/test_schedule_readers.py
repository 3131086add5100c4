"""The schedule readers (app.schedule_views): every view read back with an independent parser
(stdlib csv, the `icalendar` package, xml.etree) and checked against the schedule itself."""

from __future__ import annotations

import csv
import io
import xml.etree.ElementTree as ET
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from functools import cache

import icalendar
import pytest
from rich.console import Console

from app.domain.catalog import timed_scenario
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.scheduling.list_schedule import list_schedule
from app.domain.scheduling.schedule import Schedule, StepKind
from app.schedule_views import (
    gantt_svg,
    lanes,
    render_timeline,
    schedule_csv,
    schedule_ics,
    schedule_json,
)
from app.solvers.registry import get_solver
from benchmarks.timed_instances import construction_site

SVG = "{http://www.w3.org/2000/svg}"


@cache
def baseline() -> tuple[Problem, Schedule]:
    """The timed paper scenario, timed by the list scheduler from the exact allocation."""
    problem = Problem.build(timed_scenario("baseline_timed").instance, Mode.BALANCED)
    assignment = get_solver("optimal").solve(problem).assignment
    return problem, list_schedule(problem, assignment)


@cache
def site_1000() -> tuple[Problem, Schedule]:
    problem = Problem.build(construction_site(1000, 20, seed=0), Mode.BALANCED)
    assignment = get_solver("optimal").solve(problem).assignment
    return problem, list_schedule(problem, assignment)


def awkward() -> tuple[Problem, Schedule]:
    """Names that need escaping in every format: commas, semicolons, quotes, a newline,
    markup, a formula, non-ASCII text long enough to be folded in a calendar."""
    tasks = (
        Task(id="a,1", name='Pour; "slab", level 2', features=("heavy",), duration=30, zone="Z"),
        Task(
            id=7,
            name="Inspect\nthe rebar <cage> & ties " + "é" * 60,
            features=("heavy",),
            duration=12.5,
            zone="Z",
            after=("a,1",),
        ),
        Task(id="=SUM(A1)", name="[bold]x[/bold]", features=("heavy",), duration=5, zone="[/z]"),
    )
    robots = (Robot(name="crane, north", success={"heavy": 0.9}, zone="Z"),)
    instance = Instance(
        tasks=tasks,
        robots=robots,
        travel={"Z": {"[/z]": 2}},
        start=datetime.fromisoformat("2026-03-02T07:00:00+01:00"),
    )
    problem = Problem.build(instance, Mode.SUCCESS_FOCUSED)
    return problem, list_schedule(problem, [0, 0, 0])


CASES: dict[str, Callable[[], tuple[Problem, Schedule]]] = {
    "baseline": baseline,
    "awkward": awkward,
}


# -- lanes and JSON -------------------------------------------------------------------------


@pytest.mark.parametrize("case", CASES)
def test_lanes_tile_each_shift_in_time_order_and_idle_adds_up(case: str) -> None:
    problem, schedule = CASES[case]()
    tm = problem.instance.timing
    for r, lane in enumerate(lanes(problem, schedule)):
        shift_start = tm.shifts[r][0]
        cursor = shift_start
        for item in lane:  # contiguous: every minute of the lane is one kind of thing
            assert item.start == pytest.approx(cursor)
            assert item.end > item.start
            cursor = item.end
        worked = [item.task for item in lane if item.kind == "task"]
        assert worked == schedule.sequences(tm.n_robots)[r]
        idle = sum(item.end - item.start for item in lane if item.kind == "idle")
        assert idle == pytest.approx(schedule.robot_time[r].idle)
        travel = sum(item.end - item.start for item in lane if item.kind == "travel")
        assert travel == pytest.approx(schedule.robot_time[r].travel)


def test_json_view_is_the_schedules_dict_plus_lanes() -> None:
    problem, schedule = baseline()
    view = schedule_json(problem, schedule)
    plain = schedule.to_dict(problem)
    assert {k: v for k, v in view.items() if k != "robots"} == {
        k: v for k, v in plain.items() if k != "robots"
    }
    for name, entry in view["robots"].items():
        lane = entry.pop("lane")
        assert entry == plain["robots"][name]
        assert {i["task_id"] for i in lane if i["kind"] == "task"} == {
            t["task_id"] for t in plain["tasks"] if t["robot"] == name
        }
        assert all("task_id" not in i for i in lane if i["kind"] == "idle")


# -- CSV -------------------------------------------------------------------------------------


@pytest.mark.parametrize("case", CASES)
def test_csv_has_a_header_and_one_row_per_task(case: str) -> None:
    problem, schedule = CASES[case]()
    rows = list(csv.DictReader(io.StringIO(schedule_csv(problem, schedule), newline="")))
    assert len(rows) == problem.instance.n_tasks
    for row, slot in zip(rows, schedule.slots, strict=True):
        task = problem.instance.tasks[slot.task]
        ident = str(task.id)
        assert row["task_id"] in (ident, "'" + ident)  # a formula-like id is neutralised
        assert row["task_name"].lstrip("'") == task.name
        assert row["robot"] == problem.instance.robots[slot.robot].name
        assert float(row["start_min"]) == pytest.approx(slot.start)
        assert float(row["end_min"]) == pytest.approx(slot.end)
        assert float(row["travel_min"]) == pytest.approx(slot.travel)
        assert row["start_at"] == schedule.wall_clock(slot.start)
        assert datetime.fromisoformat(row["end_at"]) - datetime.fromisoformat(
            row["start_at"]
        ) == timedelta(minutes=slot.end - slot.start)


def test_csv_neutralises_a_formula_in_a_text_cell() -> None:
    problem, schedule = awkward()
    rows = list(csv.DictReader(io.StringIO(schedule_csv(problem, schedule), newline="")))
    assert rows[2]["task_id"] == "'=SUM(A1)"


# -- iCalendar -------------------------------------------------------------------------------


@pytest.mark.parametrize("case", CASES)
def test_ics_has_one_event_per_task_at_its_times_with_the_robot_as_resource(case: str) -> None:
    problem, schedule = CASES[case]()
    data = schedule_ics(problem, schedule, calendar_name="Site plan", uid_prefix="run-42")
    assert all(len(line) <= 75 for line in data.split(b"\r\n"))  # folded (RFC 5545 3.1)
    calendar = icalendar.Calendar.from_ical(data)
    assert str(calendar["X-WR-CALNAME"]) == "Site plan"
    events = list(calendar.walk("VEVENT"))
    assert len(events) == problem.instance.n_tasks
    assert len({str(e["UID"]) for e in events}) == len(events)
    assert schedule.start is not None
    for event, slot in zip(events, schedule.slots, strict=True):
        task, robot = problem.instance.tasks[slot.task], problem.instance.robots[slot.robot]
        start, end = event.decoded("DTSTART"), event.decoded("DTEND")
        assert start.tzinfo is not None
        assert start == schedule.start + timedelta(seconds=round(slot.start * 60))
        assert end == schedule.start + timedelta(seconds=round(slot.end * 60))
        assert str(event["RESOURCES"]) == robot.name
        assert str(event["SUMMARY"]) == f"{task.name} ({robot.display})"
        assert str(event["UID"]) == f"run-42-{task.id}"
        if slot.zone is not None:
            assert str(event["LOCATION"]) == slot.zone


def test_ics_takes_the_fallback_start_only_when_the_schedule_has_none() -> None:
    problem, schedule = awkward()
    other = datetime(2030, 1, 1, 6, 0, tzinfo=UTC)
    events = icalendar.Calendar.from_ical(
        schedule_ics(problem, schedule, calendar_name="x", uid_prefix="u", start=other)
    ).walk("VEVENT")
    assert schedule.start is not None
    assert events[0].decoded("DTSTART") == schedule.start  # its own start wins
    startless = Schedule(
        schedule.slots, schedule.makespan, schedule.robot_time, schedule.critical_path, None
    )
    events = icalendar.Calendar.from_ical(
        schedule_ics(problem, startless, calendar_name="x", uid_prefix="u", start=other)
    ).walk("VEVENT")
    assert events[0].decoded("DTSTART") == other
    with pytest.raises(ValueError, match="start"):
        schedule_ics(problem, startless, calendar_name="x", uid_prefix="u")


# -- Gantt SVG -------------------------------------------------------------------------------


def _critical(schedule: Schedule) -> set[int]:
    return {
        s.task for s in schedule.critical_path if s.kind is StepKind.TASK and s.task is not None
    }


@pytest.mark.parametrize("case", CASES)
def test_svg_has_a_lane_per_robot_a_bar_per_task_and_marks_the_critical_path(case: str) -> None:
    problem, schedule = CASES[case]()
    root = ET.fromstring(gantt_svg(problem, schedule))
    assert root.tag == f"{SVG}svg"
    groups = root.findall(f"{SVG}g[@class='robot']")
    assert [g.get("data-robot") for g in groups] == [r.name for r in problem.instance.robots]
    bars = [e for e in root.iter(f"{SVG}rect") if "task" in (e.get("class") or "").split()]
    bars = [b for b in bars if b.get("data-task") is not None]  # not the legend's swatches
    assert sorted(b.get("data-task") or "" for b in bars) == sorted(
        str(t.id) for t in problem.instance.tasks
    )
    marked = {b.get("data-task") for b in bars if "critical" in (b.get("class") or "").split()}
    tasks = problem.instance.tasks
    assert marked == {str(tasks[t].id) for t in _critical(schedule)}
    assert marked  # a non-empty schedule has a critical path
    for bar in bars:
        title = bar.find(f"{SVG}title")
        assert title is not None and (title.text or "").startswith(bar.get("data-task") or "")
    legend = " ".join(t.text or "" for t in root.iter(f"{SVG}text"))
    assert "critical path" in legend and "travel" in legend and "idle" in legend
    if any(s.travel for s in schedule.slots):
        assert root.findall(f".//{SVG}path[@class='travel']")


def test_svg_bars_sit_at_their_times() -> None:
    problem, schedule = baseline()
    root = ET.fromstring(gantt_svg(problem, schedule))
    bars = {b.get("data-task"): b for b in root.iter(f"{SVG}rect") if b.get("data-task")}
    first = max(schedule.slots, key=lambda s: s.end - s.start)
    x0 = float(bars[str(problem.instance.tasks[first.task].id)].get("x") or 0)
    widths = {
        slot.task: float(bars[str(problem.instance.tasks[slot.task].id)].get("width") or 0)
        for slot in schedule.slots
    }
    scale = widths[first.task] / (first.end - first.start)
    for slot in schedule.slots:  # every bar's x and width on the same minute scale
        bar = bars[str(problem.instance.tasks[slot.task].id)]
        assert float(bar.get("x") or 0) - x0 == pytest.approx(
            (slot.start - first.start) * scale, abs=0.2
        )
        assert widths[slot.task] == pytest.approx((slot.end - slot.start) * scale, abs=0.2)


def test_svg_of_1000_tasks_stays_small() -> None:
    problem, schedule = site_1000()
    svg = gantt_svg(problem, schedule)
    root = ET.fromstring(svg)
    bars = [b for b in root.iter(f"{SVG}rect") if b.get("data-task")]
    assert len(bars) == 1000
    # Measured 0.2 MB (docs/api.md); a chart that grows per task beyond one bar, its title
    # and a label would break this.
    assert len(svg.encode()) < 300_000


# -- the terminal timeline -------------------------------------------------------------------


@pytest.mark.parametrize("case", CASES)
def test_timeline_prints_each_robot_and_each_task(case: str) -> None:
    problem, schedule = CASES[case]()
    console = Console(record=True, width=160, color_system=None)
    render_timeline(problem, schedule, console)
    text = console.export_text()
    for robot in problem.instance.robots:
        assert robot.name in text
    for task in problem.instance.tasks:
        assert str(task.id) in text and task.name.split("\n")[0] in text
    for slot in schedule.slots:
        assert slot.zone is None or slot.zone in text  # as written, not read as markup
    assert f"makespan {schedule.makespan:g} min" in text
