"""What a revision did to the plan in time (docs/living-plans.md#the-diff-in-time:
`GET /runs/{id}/diff` adds start/end moves and the makespan before and after), from two
schedules: the parent's as it stood (its decisions re-timed by its execution reports, as
`GET /runs/{parent}/schedule` reads it) and the revision's.

Tasks are matched by id. A task is listed when its start or its end moved (by more than
`EPS`), with both times before and after in minutes of the plan and in RFC 3339 (the two
plans share their minute 0: a revision keeps its parent's `start`). Added and removed
tasks are the diff's own lists, not moves.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from app.domain.problem import Problem
from app.domain.scheduling.schedule import EPS, Schedule


@dataclass(frozen=True)
class Timed:
    """A problem and its schedule: one side of the diff."""

    problem: Problem
    schedule: Schedule


def _side(timed: Timed) -> dict[str, dict[str, Any]]:
    tasks, robots = timed.problem.instance.tasks, timed.problem.instance.robots
    return {
        str(tasks[s.task].id): {
            "task_id": tasks[s.task].id,
            "task_name": tasks[s.task].name,
            "robot": robots[s.robot].name,
            "start": s.start,
            "end": s.end,
        }
        for s in timed.schedule.slots
    }


def _makespan(timed: Timed) -> dict[str, Any]:
    return {
        "minutes": timed.schedule.makespan,
        "at": timed.schedule.wall_clock(timed.schedule.makespan),
    }


def time_moves(before: Timed, after: Timed) -> dict[str, Any]:
    """{"moves": [...], "makespan_before": {minutes, at}, "makespan_after": {minutes, at}};
    moves in the revision's queue order."""
    was = _side(before)
    moves = []
    for task_id, now in _side(after).items():
        old = was.get(task_id)
        if old is None:
            continue
        start_by, end_by = now["start"] - old["start"], now["end"] - old["end"]
        if abs(start_by) <= EPS and abs(end_by) <= EPS:
            continue
        moves.append(
            {
                "task_id": now["task_id"],
                "task_name": now["task_name"],
                "robot_before": old["robot"],
                "robot_after": now["robot"],
                "start_before": old["start"],
                "start_after": now["start"],
                "end_before": old["end"],
                "end_after": now["end"],
                "start_before_at": before.schedule.wall_clock(old["start"]),
                "start_after_at": after.schedule.wall_clock(now["start"]),
                "end_before_at": before.schedule.wall_clock(old["end"]),
                "end_after_at": after.schedule.wall_clock(now["end"]),
                "start_moved": start_by,
                "end_moved": end_by,
            }
        )
    return {
        "moves": moves,
        "makespan_before": _makespan(before),
        "makespan_after": _makespan(after),
    }
