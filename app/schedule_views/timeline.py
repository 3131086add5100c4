"""A schedule in the terminal: per robot, its tasks in time order with travel and idle
gaps (what `ltaa schedule` prints), then the makespan and the critical path."""

from __future__ import annotations

from rich.console import Console
from rich.table import Table
from rich.text import Text

from app.domain.problem import Problem
from app.domain.scheduling.schedule import Schedule
from app.schedule_views.json_view import LaneKind, critical_tasks, lanes

_STYLE = {LaneKind.TASK: "", LaneKind.TRAVEL: "yellow", LaneKind.IDLE: "dim"}


def _clock(schedule: Schedule, minute: float) -> str:
    at = schedule.wall_clock(minute)
    return "" if at is None else at[11:16]


def render_timeline(problem: Problem, schedule: Schedule, console: Console) -> None:
    instance = problem.instance
    tasks = instance.tasks
    critical = critical_tasks(schedule)
    for r, lane in enumerate(lanes(problem, schedule)):
        robot, used = instance.robots[r], schedule.robot_time[r]
        table = Table(
            title=f"{robot.display} ({robot.name})",
            caption=f"busy {used.busy:g} min, travel {used.travel:g} min, idle {used.idle:g} min",
            title_justify="left",
            caption_justify="left",
        )
        for column in ("start", "end", "min", "clock"):
            table.add_column(column, justify="right")
        table.add_column("what")
        table.add_column("zone")
        for item in lane:
            if item.kind is LaneKind.TASK and item.task is not None:
                slot = schedule.slots[item.task]
                what = Text(f"{tasks[item.task].id} {tasks[item.task].name}")
                if item.task in critical:
                    what.append(" *", style="bold red")
                zone = slot.zone or ""
            elif item.kind is LaneKind.TRAVEL and item.task is not None:
                what = Text(f"travel to {schedule.slots[item.task].zone}", style="yellow")
                zone = ""
            else:
                what, zone = Text("idle", style="dim"), ""
            table.add_row(
                f"{item.start:g}",
                f"{item.end:g}",
                f"{item.end - item.start:g}",
                _clock(schedule, item.start),
                what,
                Text(zone),  # a zone is any name: never read as markup
                style=_STYLE[item.kind],
            )
        if not lane:
            table.add_row("", "", "", "", Text("no tasks", style="dim"), "")
        console.print(table)
    path = " -> ".join(
        str(tasks[step.task].id)
        for step in schedule.critical_path
        if step.kind.value == "task" and step.task is not None
    )
    start = "" if schedule.start is None else f" from {schedule.start.isoformat()}"
    summary = Text.assemble(
        ("makespan", "bold"),
        f" {schedule.makespan:g} min{start}; ",
        ("*", "bold red"),
        f" critical path ({len(critical)} tasks): {path}",
    )
    console.print(summary, highlight=False)
