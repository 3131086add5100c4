"""Bodies of a run's audit trace: events, decisions with their attempts, chain verification."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field

from app.allocation.team_schemas import MEMBERS_FIELD, TeamMemberOut
from app.domain.lifecycle import RunStatus
from app.http.times import Timestamp
from app.runs.schemas import DecisionReviewOut, Page, StandIn
from app.runs.time_schemas import DecisionTimes


class EventOut(BaseModel):
    seq: int
    kind: str
    detail: dict[str, Any]
    at: Timestamp


class AttemptOut(BaseModel):
    attempt: int
    tier: int
    parsed: dict[str, Any] | None = Field(description="The decision as parsed from the reply")
    scores: dict[str, float] = Field(description="Per validation criterion, each in [0, 1]")
    quality: float | None = Field(description="Q = weighted sum of the scores")
    accepted: bool | None
    hard_invalid: str | None
    feedback: str | None
    input_tokens: int
    output_tokens: int
    latency_ms: float
    transport_retries: int
    model: str | None
    reasoner: str = Field(
        description="Who wrote the reply: 'anthropic', 'openai', 'rules' or 'replay'"
    )
    why: StandIn | None = Field(
        None,
        description="Set when the rules reasoner answered instead of the run's LLM: "
        "'clear-cut' (llm_scope 'contested' and the decision was not contested) or "
        "'budget_exhausted' (the run's token budget was spent) or 'gave_up' (the model "
        "failed too many tasks in a row: docs/reasoners.md#bounded-cost)",
    )
    replayed_from: str | None = Field(
        None,
        description="Replay runs: the run whose recorded reply this attempt reused "
        "(no API call; model null, tokens 0)",
    )
    original_model: str | None = Field(
        None,
        description="Replay runs: the model that wrote the recorded reply (null for "
        "the rules reasoner)",
    )
    system_prompt: str | None = Field(None, description="With ?include=prompts")
    user_prompt: str | None = Field(None, description="With ?include=prompts")
    reply: str | None = Field(None, description="Raw reply, with ?include=prompts")


# The supervisors' shape of a decision: the record with its attempts, who decided and the
# pins (why a decision has four shapes: app.graph.recorder.DecisionRecord).
class DecisionOut(DecisionTimes):
    task_index: int
    task_id: int | str
    task_name: str
    robot: str
    expected_success: float
    phase: str
    loads_before: list[int]
    loads_after: list[int]
    balance_before: float
    balance_after: float
    severity_after: str
    reasoning: str
    confidence: str
    tradeoff: str
    quality: float
    fallback: bool
    failure_log: list[str]
    regret: float | None
    reasoner: str = Field(
        description="Whose answer the decision took: the accepted attempt's reasoner, or "
        "'rules' when the fallback decided"
    )
    why: StandIn | None = Field(
        None, description="'fallback' when every attempt failed; else the accepted attempt's"
    )
    review: DecisionReviewOut | None = None
    pinned: bool = Field(
        False,
        description="Revisions: kept from the parent, not decided again "
        "(docs/living-plans.md#pins)",
    )
    pinned_from: str | None = Field(
        None, description="Of a pinned decision: the parent decision's chain hash"
    )
    team: list[TeamMemberOut] | None = MEMBERS_FIELD
    attempts: list[AttemptOut]


class TraceOut(BaseModel):
    id: str
    status: RunStatus
    reasoner: str
    mode: str
    max_deviation: float | None
    robots: list[str]
    events: list[EventOut]
    decisions: list[DecisionOut] = Field(
        description="Decisions in task order: one page of them (see decisions_page)"
    )
    decisions_page: Page


class BrokenLinkOut(BaseModel):
    """Where a run's hash chain first fails to verify."""

    table: Literal["decisions", "events", "annotations"]
    task_index: int | None = Field(description="The decision (decisions table), else null")
    seq: int | None = Field(
        description="The event (events table) or annotation (annotations table), else null"
    )
    expected: str | None = Field(
        description="The hash recomputed from the row's content and the previous link; null "
        "when the row is missing or has no stored hash"
    )
    stored: str | None = Field(description="The hash stored with the row")
    reason: str = Field(description="What this means, in plain language")


class ChainHeadsOut(BaseModel):
    decisions: str | None = Field(description="Stored hash of the newest decision")
    events: str | None = Field(description="Stored hash of the newest event")


class SignatureOut(BaseModel):
    key_id: str = Field(description="The signing key (GET /audit/public-key lists them)")
    reason: str = Field(description="When it was signed: completed (later: sign-off)")
    valid: bool = Field(description="Signed by that key, over the heads recomputed now")
    problem: str | None = Field(description="Why not, in plain language; null when valid")


class ParentLinkOut(BaseModel):
    """A revision's link to the run it revised (docs/living-plans.md#revisions)."""

    run_id: str = Field(description="The parent run")
    ok: bool = Field(
        description="The revision's chains start from the parent's heads and its change set, "
        "the parent names this run as superseded_by, and still holds those heads"
    )
    reason: str


class TraceVerifyOut(BaseModel):
    """The result of recomputing a run's three hash chains (decisions, events, and the
    annotations recorded after it finished) from its rows."""

    ok: bool = Field(description="Every row present, chained and unaltered")
    decisions: int = Field(description="Decision rows checked")
    events: int = Field(description="Event rows checked")
    annotations: int = Field(
        default=0, description="Annotation rows checked (records made after the run finished)"
    )
    annotations_head: str | None = Field(
        default=None,
        description="Stored hash of the newest annotation (records made after the run "
        "finished, such as sign-offs): outside `heads`, which is what a sign-off signs",
    )
    signoffs_ok: bool = Field(
        default=True,
        description="Every sign-off's heads are still the heads of the decision and event "
        "chains, and both verify (true when there is no sign-off)",
    )
    parent: ParentLinkOut | None = Field(
        default=None, description="Revisions: the checked link to the parent run"
    )
    unchained: int = Field(
        description="Rows with no chain hash (written before tamper evidence existed); "
        "any makes ok false"
    )
    heads: ChainHeadsOut = Field(
        description="Record these at sign-off: any later rewrite of the record changes them"
    )
    broken: BrokenLinkOut | None = Field(
        description="The first broken link (the decisions chain first), or null when ok"
    )
    chain_scheme: str = Field(
        "ltaa-trace-chain/v1",
        description="How the run's chains are built: v1, or v2 whose genesis also covers "
        "the run's immutable fields (request, mode, cap)",
    )
    signature: SignatureOut | None = Field(
        None,
        description="The check of the run's newest signature over its heads (null: not "
        "signed, e.g. no server signing key); an invalid one makes ok false",
    )
