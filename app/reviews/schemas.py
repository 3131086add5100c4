"""Bodies of the supervisor endpoints: sign-offs and (issue 12) decision reviews."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, Field

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
    robot: Name | None = Field(None, description="override only: the robot to use instead")
    reason: Annotated[str, NoNul] | None = Field(
        None, max_length=MAX_STATEMENT_CHARS, description="Why; required for an override"
    )


class ProposalOut(BaseModel):
    robot: str
    success: float
    reasoning: str
    tradeoff: str
    quality: float
    confidence: str
    fallback: bool


class AlternativeOut(BaseModel):
    robot: str
    success: float
    load: int = Field(description="The robot's load before this decision")
    cap_feasible: bool = Field(description="Whether choosing it keeps the cap satisfiable")
    regret_if_chosen: float | None = Field(
        description="Success points given away over the rest of the queue against the exact "
        "optimum if chosen (null: the cap forbids it)"
    )


class PendingReviewOut(BaseModel):
    run_id: str
    task_index: int
    task_id: int | str
    task_name: str
    proposal: ProposalOut
    triggers: list[str]
    alternatives: list[AlternativeOut]
    requested_at: Timestamp


class ReviewResolvedOut(BaseModel):
    run_id: str
    task_index: int
    action: ReviewAction
    robot: str | None = Field(description="The reviewer's robot (override), else null")
    reason: str | None
    reviewer: str = Field(description="The resolving API key's name (never the key)")
    at: Timestamp
    triggers: list[str]
    status: RunStatus = Field(description="The run's status after the resolution (queued)")
