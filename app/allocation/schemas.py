"""Request and response bodies of the HTTP API (and of `ltaa allocate --json`)."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import (
    AliasChoices,
    BaseModel,
    ConfigDict,
    Field,
    StrictFloat,
    StrictStr,
    model_validator,
)

from app.allocation.link_schemas import AfterEntry, TaskId
from app.allocation.schedule_schemas import ScheduleOut, ViolationOut
from app.allocation.team_schemas import (
    MEMBERS_FIELD,
    SKILLS_FIELD,
    TEAM_FIELD,
    TEAM_IN_FIELD,
    Team,
    TeamMemberIn,
    TeamMemberOut,
    task_features,
)
from app.allocation.timing_schemas import Duration, Minutes, PositiveMinutes, Shift, WallClock
from app.domain.metrics import Metrics
from app.domain.models import MAX_NAME_CHARS, MAX_ROBOTS, MAX_TASKS, Robot, Task
from app.domain.modes import Mode
from app.domain.objective import ObjectiveKind
from app.domain.usage import Usage
from app.http.fields import Name, NoNul

Probability = Annotated[StrictFloat, Field(ge=0.0, le=1.0, allow_inf_nan=False)]
MAX_SEED = 2**32 - 1


def _absent(value: object) -> bool:
    return value is None


# the widest seed every RNG we use (numpy, torch, random) accepts


class TaskIn(BaseModel):
    """One queued task. TEACh keys (`action_id`, `action_name`, `action_type`) are accepted."""

    # Unknown keys are ignored so TEACh action definitions can be pasted as they are.
    model_config = ConfigDict(extra="ignore")

    id: TaskId = Field(validation_alias=AliasChoices("id", "action_id"))
    name: Name | None = Field(
        None,
        validation_alias=AliasChoices("name", "action_name"),
        description="Defaults to the id as text",
    )
    type: Name = Field("Custom", validation_alias=AliasChoices("type", "action_type"))
    features: list[Name] = Field(
        default_factory=list,
        max_length=100,
        description="Features the task needs; every robot must rate each one. Required, "
        "unless `team` is given (then they are its keys)",
    )
    team: Team | None = TEAM_FIELD
    # docs/api.md#plans-in-time, all optional: a task with a duration makes the instance timed, and
    # then every task needs one.
    duration: Duration | None = None
    after: list[AfterEntry] = Field(
        default_factory=list,
        max_length=MAX_TASKS,
        description="Task ids that must end before this task starts (finish to start), or "
        'typed links {"task", "type": FS|SS|FF|SF, "lag"} (docs/schedules.md#links)',
    )
    zone: Name | None = Field(None, description="Where the task is done (see `travel`)")
    release: Minutes | None = Field(None, description="Earliest start, minutes from `start`")
    deadline: PositiveMinutes | None = Field(None, description="Latest end, minutes from `start`")

    @model_validator(mode="after")
    def _features_or_team(self) -> TaskIn:
        task_features(self.features, self.team, "features" in self.model_fields_set)
        return self

    def to_domain(self) -> Task:
        return Task(
            id=self.id,
            name=self.name if self.name is not None else str(self.id),
            type=self.type,
            features=task_features(self.features, self.team, "features" in self.model_fields_set),
            team=None if self.team is None else dict(self.team),
            duration=self.duration,
            after=tuple(self.after),
            zone=self.zone,
            release=self.release,
            deadline=self.deadline,
        )


class RobotIn(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: Name = Field(description="Key used in assignments and workloads; unique")
    label: Annotated[StrictStr, NoNul] = Field(
        "", max_length=MAX_NAME_CHARS, description="Display name, e.g. 'Light Robot'"
    )
    description: Annotated[StrictStr, NoNul] = Field("", max_length=2000)
    success: dict[Name, Probability] = Field(
        description="Success probability per feature, each in [0, 1]"
    )
    zone: Name | None = Field(None, description="Where the robot starts (timed instances)")
    available: Shift | None = None
    skills: list[Name] | None = SKILLS_FIELD

    def to_domain(self) -> Robot:
        return Robot(
            name=self.name,
            label=self.label,
            description=self.description,
            success=dict(self.success),
            zone=self.zone,
            available=self.available,
            skills=None if self.skills is None else tuple(dict.fromkeys(self.skills)),
        )


def present(field: str) -> dict[str, Any]:
    """JSON Schema: `field` is sent with a value (the server reads null as not sent)."""
    return {"required": [field], "properties": {field: {"not": {"type": "null"}}}}


def absent(field: str) -> dict[str, Any]:
    return {"not": present(field)}


# The two ways to name an instance, exclusive, one of them required.
SCENARIO_FORM: dict[str, Any] = {
    "title": "a built-in scenario",
    "allOf": [present("scenario"), absent("tasks"), absent("robots")],
}
CUSTOM_FORM: dict[str, Any] = {
    "title": "your own tasks and robots",
    "allOf": [present("tasks"), present("robots"), absent("scenario")],
}


class InstanceRequest(BaseModel):
    """What to allocate: a built-in `scenario`, or your own `tasks` and `robots` (not both)."""

    model_config = ConfigDict(
        extra="forbid", json_schema_extra={"oneOf": [SCENARIO_FORM, CUSTOM_FORM]}
    )

    scenario: Name | None = Field(None, description="A built-in scenario, see GET /scenarios")
    tasks: list[TaskIn] | None = Field(None, max_length=MAX_TASKS)
    robots: list[RobotIn] | None = Field(None, max_length=MAX_ROBOTS)
    mode: Mode = Mode.BALANCED
    max_deviation: float | None = Field(
        None,
        ge=0,
        allow_inf_nan=False,
        strict=True,
        description="Workload cap in tasks either side of the target load; omit it for the "
        "mode's default, send null for no cap",
    )
    travel: dict[Name, dict[Name, Minutes]] | None = Field(
        None,
        description='Minutes between zones, {"A": {"B": 6}}: symmetric when one direction is '
        "given, 0 inside a zone; every pair of zones in use needs an entry",
    )
    start: WallClock | None = Field(
        None,
        description="Timed instances: the wall-clock time of minute 0 (RFC 3339 with an "
        "offset; schedule times are given in that offset). Default: the request's arrival",
    )


class PinIn(BaseModel):
    """A task fixed on a robot, or a team task on its whole team
    (docs/living-plans.md#pins-in-allocate): every solver keeps it there."""

    model_config = ConfigDict(extra="forbid")

    task_id: TaskId
    robot: Name | None = Field(
        None,
        description="Robot name (or label). Required for a one-robot task; for a team task "
        "optional: the member covering its first unit, as answers read `robot`",
    )
    team: list[TeamMemberIn] | None = TEAM_IN_FIELD
    start: Minutes | None = Field(
        None, description="Timed instances: the task's fixed start (it started or is done)"
    )


class AllocateRequest(InstanceRequest):
    solver: Name = Field(description="See GET /solvers")
    seed: int = Field(0, ge=0, le=MAX_SEED, strict=True)
    options: dict[str, Any] = Field(default_factory=dict, description="Solver-specific options")
    pinned: list[PinIn] = Field(
        default_factory=list,
        max_length=MAX_TASKS,
        description="Tasks fixed on robots; solvers decide only the other tasks",
    )
    unavailable: list[Name] = Field(
        default_factory=list,
        max_length=MAX_ROBOTS,
        description="Robots that keep their pins but take no new task and are outside the "
        "balance: W = (unpinned tasks + tasks pinned on available robots) / available robots",
    )
    objective: ObjectiveKind = Field(
        ObjectiveKind.SUCCESS_THEN_MAKESPAN,
        description="Timed instances: 'success_then_makespan' (the highest expected success "
        "under the cap, then the shortest makespan) or 'makespan' (the shortest makespan "
        "whose expected success is at least min_expected_success)",
    )
    min_expected_success: float = Field(
        0.0, ge=0, le=1, strict=True, allow_inf_nan=False, description="With 'makespan' only"
    )


class Assignment(BaseModel):
    task_id: int | str
    task_name: str
    robot: str = Field(description="The robot; for a team task the member covering its first unit")
    success: float
    team: list[TeamMemberOut] | None = MEMBERS_FIELD
    # Omitted unless true, so a request without pins gets exactly the response it always did.
    pinned: bool = Field(
        False,
        description="Present (true) only for a task fixed by the request's `pinned`",
        exclude_if=lambda pinned: not pinned,
    )
    # Timed instances only, and the same fields a timed run's assignments carry
    # (docs/schedules.md): a client reads one shape from /allocate and from /runs.
    start: float | None = Field(
        None,
        description="Timed instances: start, minutes from the plan's start (as in "
        "`schedule.tasks`); absent when the assignment has no schedule",
        exclude_if=_absent,
    )
    end: float | None = Field(None, description="Timed instances: end, minutes", exclude_if=_absent)
    start_at: str | None = Field(
        None,
        description="Timed instances with a `start`: start on the wall clock (RFC 3339)",
        exclude_if=_absent,
    )
    end_at: str | None = Field(
        None,
        description="Timed instances with a `start`: end on the wall clock (RFC 3339)",
        exclude_if=_absent,
    )
    zone: str | None = Field(
        None, description="Timed instances: the task's zone, if it has one", exclude_if=_absent
    )
    travel: float | None = Field(
        None,
        description="Timed instances: minutes the robot travelled just before the task",
        exclude_if=_absent,
    )


class CompletionOut(BaseModel):
    mean: float
    ci95: tuple[float, float]
    trials: int


class MetricsOut(BaseModel):
    expected_success: float
    balance_score: float
    max_deviation: float = Field(description="Largest |load - target| actually reached")
    imbalance_severity: Literal["low", "moderate", "high", "critical"]
    workload: dict[str, int]
    feature_success: dict[str, float]
    jain_index: float
    simulated_completion: CompletionOut

    @classmethod
    def from_domain(cls, m: Metrics) -> MetricsOut:
        c = m.simulated_completion
        return cls(
            expected_success=m.expected_success,
            balance_score=m.balance_score,
            max_deviation=m.max_deviation,
            imbalance_severity=m.imbalance_severity.value,
            workload=m.workload,
            feature_success=m.feature_success,
            jain_index=m.jain_index,
            simulated_completion=CompletionOut(mean=c.mean, ci95=c.ci95, trials=c.trials),
        )


class UsageOut(BaseModel):
    llm_calls: int = 0
    input_tokens: int = 0
    output_tokens: int = 0

    @classmethod
    def from_domain(cls, u: Usage) -> UsageOut:
        # Transport retries and latency stay internal: the contract is these three counts.
        return cls(
            llm_calls=u.llm_calls, input_tokens=u.input_tokens, output_tokens=u.output_tokens
        )


class AllocateResponse(BaseModel):
    solver: str
    mode: Mode
    max_deviation: int | float | None = Field(
        description="The workload cap applied (request override or mode default); null = no cap"
    )
    assignments: list[Assignment] = Field(description="One per task, in queue order")
    metrics: MetricsOut
    usage: UsageOut
    elapsed_ms: float
    # docs/api.md#plans-in-time, on timed instances only (absent otherwise, so untimed answers are
    # unchanged).
    schedule: ScheduleOut | None = Field(
        None, description="Timed instances: when each task runs", exclude_if=_absent
    )
    schedule_model: str | None = Field(
        None,
        description="Which part is exact: CP-SAT decided robots and times together "
        "(`schedule`), or the list scheduler timed another method's assignment",
        exclude_if=_absent,
    )
    schedule_violations: list[ViolationOut] | None = Field(
        None,
        description="Rules the list scheduler's timing of the method's assignment breaks "
        "(e.g. a deadline); empty when it breaks none",
        exclude_if=_absent,
    )
    schedule_error: str | None = Field(
        None,
        description="Why the method's assignment has no schedule (a robot that cannot take a task)",
        exclude_if=_absent,
    )
    status: Literal["optimal", "feasible"] | None = Field(
        None,
        description="`schedule`: 'optimal' only when CP-SAT proved the makespan",
        exclude_if=_absent,
    )
    bound: float | None = Field(
        None, description="`schedule`: a proven lower bound on the makespan", exclude_if=_absent
    )
    gap: float | None = Field(
        None, description="`schedule`: (makespan - bound) / makespan", exclude_if=_absent
    )
    model: str | None = Field(
        None, description="`schedule`: which CP-SAT model ran", exclude_if=_absent
    )
    bound_source: str | None = Field(
        None,
        description="`schedule`: what gives `bound` ('proven optimal', 'CP-SAT search', "
        "'critical path (shortest durations)', 'heads and tails over the robots able', a "
        "load bound); docs/schedules.md#bounds",
        exclude_if=_absent,
    )
    search: dict[str, Any] | None = Field(
        None,
        description="`schedule`: the deterministic budget the search had and used, its "
        "workers and seed, and `wall_cut` (true when the wall-clock safety net stopped it); "
        "docs/schedules.md#deterministic-search",
        exclude_if=_absent,
    )


class SolverOut(BaseModel):
    name: str
    description: str
    exact: bool
    kind: Literal["exact", "approximate"]
    limits: str


class TaskOut(BaseModel):
    id: int | str
    name: str
    type: str
    features: list[str]
    # docs/api.md#plans-in-time, on a timed scenario only (left out of an untimed one's tasks)
    duration: float | dict[str, float] | None = None
    after: list[int | str] | None = None
    zone: str | None = None
    release: float | None = None
    deadline: float | None = None
    team: dict[str, int] | None = Field(
        None, description="Robots needed at once, per feature (docs/allocation.md#teams)"
    )


class RobotOut(BaseModel):
    name: str
    label: str
    description: str
    success: dict[str, float]
    zone: str | None = None  # timed scenarios only, as `available`
    available: list[float] | None = None


class ScenarioOut(BaseModel):
    name: str
    description: str
    timed: bool = Field(
        description="Its tasks have durations, zones and precedence (docs/api.md#plans-in-time): "
        "every answer "
        "about it carries a schedule"
    )
    team: bool = Field(
        False,
        description="Some of its tasks need several robots at once (docs/allocation.md#teams); "
        "plan it with optimal, dp, brute_force, greedy or schedule",
    )
    tasks: list[TaskOut]
    robots: list[RobotOut]
    travel: dict[str, dict[str, float]] | None = None
    start: datetime | None = None
