"""Bodies of the supervisor endpoints: sign-offs and (issue 12) decision reviews."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, Field

from app.allocation.team_schemas import TeamMemberIn, TeamMemberOut
from app.domain.lifecycle import RunStatus
from app.domain.review import ReviewAction
from app.http.fields import Name, NoNul
from app.http.times import Timestamp

MAX_STATEMENT_CHARS = 4000


class SignOffRequest(BaseModel):
    model_config = {"extra": "forbid"}

    statement: Annotated[str, NoNul] = Field(
        min_length=1,
        max_length=MAX_STATEMENT_CHARS,
        description="What the supervisor states about the run, recorded with their name",
    )


class ReviewRequest(BaseModel):
    model_config = {"extra": "forbid"}

    action: ReviewAction = Field(description="'approve' the proposal, or 'override' it")
    robot: Name | None = Field(
        None,
        description="override only: the robot to use instead (a team decision takes `team`; "
        "`robot` beside it must be the member covering the first unit)",
    )
    team: list[TeamMemberIn] | None = Field(
        None,
        min_length=1,
        max_length=100,
        description="override of a team decision only (docs/reviews.md#reviews-of-team-decisions):"
        ' the team to use instead, one {"robot", "feature"} per unit, each robot distinct and '
        "able to cover its feature, the team within the workload cap",
    )
    reason: Annotated[str, NoNul] | None = Field(
        None, max_length=MAX_STATEMENT_CHARS, description="Why; required for an override"
    )


TEAM_OUT = Field(
    None,
    description="A team decision (docs/reviews.md#reviews-of-team-decisions): one entry per "
    "unit, in the team's key order; `robot` is the first unit's member",
    exclude_if=lambda members: members is None,
)


class ProposalOut(BaseModel):
    robot: str
    team: list[TeamMemberOut] | None = TEAM_OUT
    success: float
    reasoning: str
    tradeoff: str
    quality: float
    confidence: str
    fallback: bool


class AlternativeOut(BaseModel):
    robot: str
    team: list[TeamMemberOut] | None = TEAM_OUT
    success: float
    load: int = Field(
        description="The robot's load before this decision (a team: its members' loads summed)"
    )
    cap_feasible: bool = Field(description="Whether choosing it keeps the cap satisfiable")
    regret_if_chosen: float | None = Field(
        description="Success points given away over the rest of the queue against the exact "
        "optimum if chosen (null: the cap forbids it)"
    )


class TeamUnitOut(BaseModel):
    feature: str
    count: int = Field(description="Units of this feature the team needs")
    robots: list[str] = Field(
        description="Robots that may cover one (eligible, room under the cap)"
    )


class PendingReviewOut(BaseModel):
    run_id: str
    task_index: int
    task_id: int | str
    task_name: str
    proposal: ProposalOut
    triggers: list[str]
    alternatives: list[AlternativeOut] = Field(
        description="Every robot; on a team decision the rules reasoner's candidate teams, the "
        "best by success first (docs/reviews.md#reviews-of-team-decisions)"
    )
    units: list[TeamUnitOut] | None = Field(
        None,
        description="A team decision: per feature of the team, its units and the robots that "
        "may cover one now",
        exclude_if=lambda units: units is None,
    )
    requested_at: Timestamp


class ReviewResolvedOut(BaseModel):
    run_id: str
    task_index: int
    action: ReviewAction
    robot: str | None = Field(description="The reviewer's robot (override), else null")
    team: list[TeamMemberOut] | None = Field(
        None,
        description="The reviewer's team (override of a team decision), in unit order",
        exclude_if=lambda members: members is None,
    )
    reason: str | None
    reviewer: str = Field(description="The resolving API key's name (never the key)")
    at: Timestamp
    triggers: list[str]
    status: RunStatus = Field(description="The run's status after the resolution (queued)")
