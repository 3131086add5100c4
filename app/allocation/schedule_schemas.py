"""The schedule block of an answer on a timed instance (docs/schedules.md#a-schedule-and-its-check).

Its content is built by `app.schedule_views.schedule_json` (the one JSON view of a schedule,
also what `ltaa schedule --format json` prints); these models only describe it for the
OpenAPI document and check that the answer keeps to it.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field


class ScheduledMemberOut(BaseModel):
    robot: str
    feature: str = Field(description="The feature of the unit this member covers")
    travel: float = Field(description="Minutes this member moved just before the task")


class ScheduledTaskOut(BaseModel):
    task_id: int | str
    robot: str = Field(description="The robot; for a team task the member covering its first unit")
    start: float = Field(description="Minutes from the plan's start")
    end: float
    start_at: str | None = Field(description="RFC 3339, in the offset of the plan's start")
    end_at: str | None
    zone: str | None
    travel: float = Field(description="Minutes the robot moved just before this task")
    team: list[ScheduledMemberOut] | None = Field(
        None,
        description="Team tasks only (docs/allocation.md#teams): every member, one per unit "
        "in the team's key order, busy over the same start and end",
        exclude_if=lambda members: members is None,
    )


class LaneItemOut(BaseModel):
    kind: Literal["travel", "idle", "task"]
    start: float
    end: float
    task_id: int | str | None = Field(
        None,
        description="The task worked (task) or travelled to (travel); absent when idle",
        exclude_if=lambda v: v is None,
    )


class RobotScheduleOut(BaseModel):
    busy: float = Field(description="Minutes working")
    idle: float = Field(
        description="Minutes of its shift, up to the makespan, spent neither working nor travelling"
    )
    travel: float = Field(description="Minutes travelling between zones")
    lane: list[LaneItemOut] = Field(description="Its travel, idle gaps and tasks in time order")


class CriticalStepOut(BaseModel):
    kind: Literal["task", "travel", "wait"]
    task_id: int | str | None
    robot: str | None
    start: float
    end: float
    cause: str = Field(description="Why the next step could not start earlier")


class ScheduleOut(BaseModel):
    start: str | None = Field(description="Wall-clock time of minute 0 (RFC 3339)")
    makespan: float = Field(description="Minutes from the plan's start to the last task's end")
    tasks: list[ScheduledTaskOut] = Field(description="One per task, in queue order")
    robots: dict[str, RobotScheduleOut]
    critical_path: list[CriticalStepOut] = Field(
        description="The chain of tasks, travel and waits that fixes the makespan"
    )


class ViolationOut(BaseModel):
    rule: str = Field(description="e.g. 'deadline', 'precedence', 'shift', 'overlap'")
    message: str
    task_id: int | str | None
    robot: str | None
