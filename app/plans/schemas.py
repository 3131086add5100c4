"""Bodies of the living-plan endpoints (docs/living-plans.md): execution reports and revisions."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictInt, StrictStr

from app.allocation.schemas import Probability, RobotIn, TaskId, TaskIn
from app.allocation.team_schemas import TeamMemberOut
from app.domain.estimates import DurationSource, RateSource
from app.domain.lifecycle import RunStatus
from app.domain.models import MAX_ROBOTS, MAX_TASKS
from app.domain.modes import Mode
from app.http.fields import Name, NoNul
from app.http.times import RequestTime, Timestamp

MAX_UPDATES = 10_000
MAX_CHANGES = 100


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ExecutionUpdate(_Strict):
    task_id: TaskId
    state: Literal["started", "done", "failed"]
    at: RequestTime | None = Field(
        None,
        description="When it happened: RFC 3339 with an offset (Z or +05:00), stored in UTC; "
        "default now",
    )


class ExecutionRequest(_Strict):
    updates: list[ExecutionUpdate] = Field(min_length=1, max_length=MAX_UPDATES)


class ExecutionOut(BaseModel):
    run_id: str
    states: dict[str, str] = Field(description="Each reported task's state now, by task id")


class RobotUnavailable(_Strict):
    type: Literal["robot_unavailable"]
    robot: Name


class RobotAvailable(_Strict):
    type: Literal["robot_available"]
    robot: Name


class SetRates(_Strict):
    type: Literal["set_rates"]
    robot: Name
    success: dict[Name, Probability] = Field(min_length=1, max_length=100)


class AddRobot(_Strict):
    type: Literal["add_robot"]
    robot: RobotIn


class AddTasks(_Strict):
    type: Literal["add_tasks"]
    tasks: list[TaskIn] = Field(min_length=1, max_length=MAX_TASKS)
    position: Literal["next", "end"] = "end"


class RemoveTasks(_Strict):
    type: Literal["remove_tasks"]
    task_ids: list[TaskId] = Field(min_length=1, max_length=MAX_TASKS)


class SetMode(_Strict):
    type: Literal["set_mode"]
    mode: Mode
    max_deviation: float | None = Field(
        None, ge=0, allow_inf_nan=False, strict=True, description="Omit for the mode's default"
    )


class UseLearned(_Strict):
    """docs/estimates.md#using-the-estimates: these robots (default: every robot) plan with the
    site's learned rates now, their configured rates the priors."""

    type: Literal["use_learned"]
    robots: list[Name] | None = Field(None, min_length=1, max_length=MAX_ROBOTS)


class Delay(_Strict):
    """docs/living-plans.md#a-revision-in-time: the task takes this many minutes longer, on every
    robot (timed runs only)."""

    type: Literal["delay"]
    task_id: TaskId
    minutes: float = Field(gt=0, le=525_600, allow_inf_nan=False, description="Minutes added")


Change = Annotated[
    RobotUnavailable
    | RobotAvailable
    | SetRates
    | AddRobot
    | AddTasks
    | RemoveTasks
    | SetMode
    | UseLearned
    | Delay,
    Field(discriminator="type"),
]


class PinThrough(_Strict):
    through_task_index: StrictInt = Field(ge=0, le=MAX_TASKS)


class PinTasks(_Strict):
    task_ids: list[TaskId] = Field(min_length=1, max_length=MAX_TASKS)


class RevisionRequestIn(_Strict):
    """A revision of a run: the changes, which decisions stay (pins), and why."""

    changes: list[Change] = Field(default_factory=list, max_length=MAX_CHANGES)
    pin: Literal["reported", "decided"] | PinThrough | PinTasks = Field(
        "reported",
        description="'reported' (tasks reported started or done), 'decided' (every task the "
        "parent decided), {through_task_index: k} or {task_ids: [...]}",
    )
    reason: Annotated[StrictStr, NoNul] = Field(min_length=1, max_length=2000)
    reasoner: Name | None = Field(None, description="Override the inherited reasoner")
    model: Name | None = Field(None, description="Override the inherited model")
    rates: RateSource | None = Field(
        None,
        description="'configured', 'learned' or 'sampled' (default: the parent's; "
        "docs/estimates.md#using-the-estimates). "
        "Learned and sampled rates are the site's estimates when the revision is made",
    )
    durations: DurationSource | None = Field(
        None, description="'configured' or 'learned' (default: the parent's)"
    )
    now: RequestTime | None = Field(
        None,
        description="Timed runs (docs/living-plans.md#a-revision-in-time): the time the revision "
        "plans from (RFC 3339 with an "
        "offset; default: the request's arrival). Nothing unstarted is planned earlier; it may "
        "not be before the plan's start",
    )


class RevisionCreated(BaseModel):
    id: str
    revision_of: str
    revision: int
    status: RunStatus
    location: str


class RevisionItem(BaseModel):
    id: str
    revision: int
    revision_of: str | None
    superseded_by: str | None
    status: RunStatus
    created_at: Timestamp
    reason: str | None = Field(
        None, description="Why the revision was made, as its request said (None: the original)"
    )


class RobotChange(BaseModel):
    task_id: int | str
    task_name: str
    from_robot: str
    to_robot: str
    success_before: float
    success_after: float
    # docs/living-plans.md#teams-in-a-revision: a team task's members before and after.
    from_team: list[TeamMemberOut] | None = Field(
        None,
        description="A team task: its members in the parent (one per unit)",
        exclude_if=lambda v: v is None,
    )
    to_team: list[TeamMemberOut] | None = Field(
        None,
        description="A team task: its members in the revision (one per unit)",
        exclude_if=lambda v: v is None,
    )
    members_left: list[str] | None = Field(
        None,
        description="A team task: robots that were members and are no longer",
        exclude_if=lambda v: v is None,
    )
    members_joined: list[str] | None = Field(
        None,
        description="A team task: robots that joined its team",
        exclude_if=lambda v: v is None,
    )


class SideMetrics(BaseModel):
    expected_success: float | None
    balance_score: float | None
    decided: int
    total: int


class PlanMinute(BaseModel):
    minutes: float = Field(description="Minutes from the plan's start")
    at: str | None = Field(description="RFC 3339, in the plan's offset")


class TaskMove(BaseModel):
    task_id: int | str
    task_name: str
    robot_before: str
    robot_after: str
    start_before: float
    start_after: float
    end_before: float
    end_after: float
    start_before_at: str | None
    start_after_at: str | None
    end_before_at: str | None
    end_after_at: str | None
    start_moved: float = Field(description="Minutes later (negative: earlier)")
    end_moved: float


class ScheduleDiff(BaseModel):
    """docs/living-plans.md#the-runs-current-schedule: the parent's current schedule (its decisions
    re-timed by its execution reports) against the revision's."""

    moves: list[TaskMove] = Field(description="Tasks whose start or end moved, queue order")
    makespan_before: PlanMinute
    makespan_after: PlanMinute


class DiffOut(BaseModel):
    run_id: str
    parent: str
    robot_changes: list[RobotChange]
    added_tasks: list[int | str]
    removed_tasks: list[int | str]
    fleet_changes: list[dict[str, object]]
    before: SideMetrics
    after: SideMetrics
    schedule: ScheduleDiff | None = Field(
        None,
        description="Timed runs only (docs/living-plans.md#the-diff-in-time): start/end moves "
        "and the makespans",
    )


__all__ = ["MAX_ROBOTS"]
