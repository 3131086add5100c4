"""The JSON view of a schedule, and the per-robot lanes every other view draws from.

A team task (docs/allocation.md#teams) is in every member's lane over the same times, each
member's travel before it its own.

A lane is a robot's time from its shift start to the end of its shift or the makespan,
whichever comes first, cut into its tasks, the travel just before each task and the idle
gaps left over. Travel is drawn right before the task it leads to: a schedule fixes when a
task starts, not when the robot sets off, and leaving at the last moment is what the
critical path assumes too. The idle minutes of a lane add up to the robot's `idle` in
`Schedule.robot_time` whenever its tasks lie inside its shift.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from app.domain.problem import Problem
from app.domain.scheduling.feasibility import Violation
from app.domain.scheduling.schedule import EPS, Schedule, StepKind


class LaneKind(StrEnum):
    TRAVEL = "travel"
    IDLE = "idle"
    TASK = "task"


@dataclass(frozen=True)
class LaneItem:
    kind: LaneKind
    start: float
    end: float
    task: int | None  # the task worked (task) or travelled to (travel); None when idle


def lanes(problem: Problem, schedule: Schedule) -> list[list[LaneItem]]:
    """Per robot (fleet order), its travel, idle gaps and tasks in time order."""
    tm = problem.instance.timing
    out: list[list[LaneItem]] = []
    for r, sequence in enumerate(schedule.sequences(tm.n_robots)):
        shift_start, shift_end = tm.shifts[r]
        cursor = shift_start
        lane: list[LaneItem] = []
        for t in sequence:
            slot = schedule.slots[t]
            travel = slot.travel_of(r)  # a team task: this member's own way there
            leave = slot.start - travel
            if leave - cursor > EPS:
                lane.append(LaneItem(LaneKind.IDLE, cursor, leave, None))
            if travel > EPS:
                lane.append(LaneItem(LaneKind.TRAVEL, leave, slot.start, t))
            lane.append(LaneItem(LaneKind.TASK, slot.start, slot.end, t))
            cursor = max(cursor, slot.end)
        until = min(shift_end, schedule.makespan)
        if until - cursor > EPS:
            lane.append(LaneItem(LaneKind.IDLE, cursor, until, None))
        out.append(lane)
    return out


def critical_tasks(schedule: Schedule) -> frozenset[int]:
    """The tasks worked on the critical path."""
    return frozenset(
        step.task
        for step in schedule.critical_path
        if step.kind is StepKind.TASK and step.task is not None
    )


def schedule_json(problem: Problem, schedule: Schedule) -> dict[str, Any]:
    """The schedule block of an answer: `Schedule.to_dict` with each robot's lane."""
    out = schedule.to_dict(problem)
    tasks = problem.instance.tasks
    for robot, lane in zip(problem.instance.robots, lanes(problem, schedule), strict=True):
        out["robots"][robot.name]["lane"] = [
            {"kind": item.kind.value, "start": item.start, "end": item.end}
            | ({} if item.task is None else {"task_id": tasks[item.task].id})
            for item in lane
        ]
    return out


def violations_json(problem: Problem, violations: list[Violation]) -> list[dict[str, Any]]:
    """The rules a schedule breaks, naming tasks by id and robots by name."""
    tasks, robots = problem.instance.tasks, problem.instance.robots
    return [
        {
            "rule": v.rule.value,
            "message": v.message,
            "task_id": None if v.task is None else tasks[v.task].id,
            "robot": None if v.robot is None else robots[v.robot].name,
        }
        for v in violations
    ]
