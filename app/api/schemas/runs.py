"""Bodies of the /runs endpoints: the durable LTAA runs and their audit trace."""

from __future__ import annotations

import re
from datetime import UTC, datetime
from typing import Annotated, Any, Literal, cast

from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field
from pydantic.config import JsonDict
from pydantic_core import PydanticCustomError

from app.api.schemas.allocation import (
    CUSTOM_FORM,
    MAX_SEED,
    SCENARIO_FORM,
    InstanceRequest,
    MetricsOut,
    Name,
    TaskId,
    UsageOut,
    absent,
    present,
)
from app.domain.lifecycle import RunStatus
from app.domain.review import ReviewAction, ReviewOn
from app.store.models import as_utc

StandIn = Literal["clear-cut", "budget_exhausted", "fallback"]
# Run ids are uuid4 hex; the pattern is looser on purpose, and only keeps out what a
# database may refuse in a query (PostgreSQL rejects a NUL character with an error, a 500).
RUN_ID_PATTERN = r"^[A-Za-z0-9_-]+$"


# A date-time without an offset is not RFC 3339 (OpenAPI's format): a client cannot place
# it, and SQLite hands stored times back without one.
Timestamp = Annotated[datetime, AfterValidator(as_utc)]

_EXAMPLE = "e.g. 2026-12-01T09:30:00Z or 2026-12-01T09:30:00+05:00"
_DATE_TIME = r"\d{4}-\d{2}-\d{2}[Tt]\d{2}:\d{2}:\d{2}(?:\.\d+)?"
_RFC3339 = re.compile(_DATE_TIME + r"(?:[Zz]|[+-]\d{2}:\d{2})")
_NO_OFFSET = re.compile(_DATE_TIME)


def _rfc3339_utc(value: object) -> datetime:
    """An RFC 3339 date-time string, offset required, as the same instant in UTC.

    Pydantic alone would take a bare number as seconds since 1970 and a time without an
    offset as it is (stored as if it were UTC, while the client may have meant local time),
    and SQLite drops an offset: every stored time is UTC, so convert here."""
    if not isinstance(value, str):
        raise PydanticCustomError(
            "datetime_type", f"must be an RFC 3339 date-time string with an offset, {_EXAMPLE}"
        )
    if _NO_OFFSET.fullmatch(value):
        raise PydanticCustomError(
            "timezone_aware",
            f"has no offset: add Z (UTC) or the site's offset such as +05:00, {_EXAMPLE}",
        )
    if not _RFC3339.fullmatch(value):
        raise PydanticCustomError(
            "datetime_parsing",
            f"must be an RFC 3339 date-time with an offset, {_EXAMPLE}",
        )
    try:
        parsed = datetime.fromisoformat(value.upper())
    except ValueError as exc:
        raise PydanticCustomError(
            "datetime_parsing", "is not a valid date-time: {error}", {"error": str(exc)}
        ) from None
    try:
        return parsed.astimezone(UTC)
    except OverflowError:
        raise PydanticCustomError(
            "datetime_out_of_range",
            "is out of range: in UTC it falls outside the years 0001 to 9999",
        ) from None


# A time in a request: RFC 3339 with an offset (the OpenAPI date-time format), held in UTC.
RequestTime = Annotated[datetime, BeforeValidator(_rfc3339_utc)]


# A replay copies its source's instance: it may omit it (or repeat it, the forms above).
REPLAY_FORM: dict[str, Any] = {
    "title": "a replay of a completed run",
    "allOf": [present("replay_of"), absent("scenario"), absent("tasks"), absent("robots")],
}
# replay_of goes with the replay reasoner and only with it (an omitted reasoner is the
# server's default, never "replay").
REPLAY_PAIRING: list[dict[str, Any]] = [
    {
        "if": present("replay_of"),
        "then": {"required": ["reasoner"], "properties": {"reasoner": {"const": "replay"}}},
    },
    {
        "if": {"required": ["reasoner"], "properties": {"reasoner": {"const": "replay"}}},
        "then": present("replay_of"),
    },
]


class ReviewPolicyIn(BaseModel):
    """Which decisions wait for a supervisor (SPEC 11). A decision needs review when any
    listed condition holds; the run pauses before the decision is stored."""

    model_config = {"extra": "forbid"}

    on: list[ReviewOn] = Field(
        default_factory=list,
        max_length=3,
        description="'fallback' (the rules fallback decided), 'low_confidence' (the accepted "
        "reply's Confidence Level is Low), 'every_decision'",
    )
    quality_below: float | None = Field(
        None, ge=0, le=1, allow_inf_nan=False, description="Review when Q is below this"
    )
    regret_above: float | None = Field(
        None,
        ge=0,
        allow_inf_nan=False,
        description="Review when the proposal gives away more than this many success points "
        "over the rest of the queue against the exact optimum (the unit of the guidance "
        "costs, not divided by the number of tasks)",
    )
    task_ids: list[TaskId] = Field(
        default_factory=list, max_length=10_000, description="Review these tasks"
    )
    features: list[Name] = Field(
        default_factory=list, max_length=100, description="Review tasks needing any of these"
    )
    robots: list[Name] = Field(
        default_factory=list,
        max_length=100,
        description="Review decisions proposing any of these robots",
    )


class RunRequest(InstanceRequest):
    """An LTAA run on an instance, executed durably in the background."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra=cast(
            JsonDict,
            {"anyOf": [SCENARIO_FORM, CUSTOM_FORM, REPLAY_FORM], "allOf": REPLAY_PAIRING},
        ),
    )

    reasoner: Name | None = Field(
        None,
        description="'rules' (default, offline), 'anthropic', 'openai' (the server's "
        "OpenAI-compatible endpoint, LTAA_OPENAI_BASE_URL), or 'replay' (with replay_of)",
    )
    quality_threshold: float = Field(
        0.6,
        ge=0,
        le=1,
        strict=True,
        allow_inf_nan=False,
        description="Accept a reply when Q >= this",
    )
    max_retries: int = Field(
        3,
        ge=0,
        le=10,
        strict=True,
        description="Validation retries (tiers 1-3) before the fallback",
    )
    model: Name | None = Field(
        None,
        description="Model name: Claude (anthropic) or the OpenAI-compatible server's "
        "(openai; default LTAA_OPENAI_MODEL)",
    )
    temperature: float | None = Field(
        None,
        ge=0,
        le=1,
        strict=True,
        allow_inf_nan=False,
        description="Sampling temperature (default 0.1)",
    )
    guidance: Literal["optimizer"] | None = Field(
        None, description="'optimizer': the prompt carries the optimal completion's choice"
    )
    seed: int = Field(
        0, ge=0, le=MAX_SEED, strict=True, description="Seed of the simulated-completion metric"
    )
    token_budget: int | None = Field(
        None,
        ge=1,
        strict=True,
        description="LLM tokens (input + output) the run may spend; once spent, the "
        "remaining tasks use the offline 'rules' reasoner (default: the server's setting)",
    )
    llm_scope: Literal["all", "contested"] | None = Field(
        None,
        description="'all' (default, the paper): every decision asks the LLM. 'contested': "
        "only decisions whose trade-off verdict is within llm_margin points of its threshold, "
        "or where optimizer guidance disagrees with the rule, ask the LLM; the rules reasoner "
        "answers the clear-cut ones (their attempts say reasoner 'rules', why 'clear-cut'). "
        "No effect with the 'rules' reasoner",
    )
    llm_margin: float | None = Field(
        None,
        ge=0,
        le=100,
        strict=True,
        allow_inf_nan=False,
        description="Points either side of the threshold within which a decision is "
        "contested (default 5)",
    )
    review: ReviewPolicyIn | None = Field(
        None, description="Supervisor review of decisions (default: none); see GET /reviews"
    )
    replay_of: str | None = Field(
        None,
        min_length=1,
        max_length=64,
        pattern=RUN_ID_PATTERN,
        description="Required by reasoner 'replay', refused with any other: id of a completed "
        "run whose recorded replies are replayed, with no API call. The replay copies that "
        "run's instance, mode, max_deviation, quality_threshold, max_retries, guidance, "
        "seed, llm_scope and llm_margin: omit them, or send the original's values (any "
        "other value is a 422 naming the field); model, temperature and token_budget do "
        "not apply; review is refused (the replay re-applies the original's review "
        "settings and recorded resolutions). Unknown id: 422; a run not completed: 409",
    )


class RunCreated(BaseModel):
    id: str
    status: RunStatus
    location: str


class Progress(BaseModel):
    allocated: int
    total: int
    phase: Literal["early", "middle", "late"]


DEFAULT_PAGE = 1_000
MAX_PAGE = 10_000


class Page(BaseModel):
    """Which slice of a long list this answer carries; ask for the next with
    `offset=offset+limit` while `offset + limit < total`."""

    offset: int = Field(description="Index (in queue order) of the first item returned")
    limit: int = Field(description="At most this many items returned")
    total: int = Field(description="Items in the whole list")


class DecisionReviewOut(BaseModel):
    """A supervisor's review of a decision (SPEC 11); covered by the decision's chain hash."""

    action: ReviewAction
    reviewer: str = Field(description="The resolving API key's name")
    reason: str | None
    at: Timestamp
    triggers: list[str]
    overridden_from: str | None = Field(
        None, description="override: the robot the run had proposed"
    )


class ExecutionStateOut(BaseModel):
    state: Literal["started", "done", "failed"]
    started_at: Timestamp | None
    ended_at: Timestamp | None


class RunAssignment(BaseModel):
    task_index: int
    task_id: int | str
    task_name: str
    robot: str
    success: float
    fallback: bool
    review: DecisionReviewOut | None = None
    pinned: bool = Field(False, description="Revisions: kept from the parent (SPEC 10)")
    execution: ExecutionStateOut | None = Field(
        None, description="The latest execution report on this task, if any"
    )


class SignedHeadsOut(BaseModel):
    decisions: str | None = Field(description="Head of the decision chain when signed")
    events: str | None = Field(description="Head of the event chain when signed")


class SignOffOut(BaseModel):
    signer: str = Field(description="The signing API key's name (never the key)")
    at: Timestamp
    heads: SignedHeadsOut = Field(
        description="The chain heads signed; trace/verify's signoffs_ok says whether the "
        "record still ends there"
    )
    statement: str


class RunOut(BaseModel):
    id: str
    status: RunStatus
    reasoner: str
    mode: str
    max_deviation: float | None
    progress: Progress
    workload: dict[str, int]
    assignments: list[RunAssignment] = Field(
        description="Decisions so far, in queue order: one page of them (see assignments_page)"
    )
    assignments_page: Page
    metrics: MetricsOut | None = Field(description="Set once the run has completed")
    regret: float | None = Field(
        description="Sum of the per-decision regrets so far: expected success given away "
        "against the exact optimum (once completed, equals optimal's minus the run's)"
    )
    usage: UsageOut
    resumes: int
    graph_version: str | None = Field(
        description="The graph version the run started under (null: not started yet, or "
        "before versions were recorded)"
    )
    error: str | None
    revision_of: str | None = Field(None, description="The run this one revises")
    revision: int = Field(0, description="Place in the lineage: 0 for a root run")
    superseded_by: str | None = Field(None, description="The revision that replaced this run")
    created_at: Timestamp
    updated_at: Timestamp
    finished_at: Timestamp | None
    signoffs: list[SignOffOut] = Field(
        default_factory=list, description="Sign-offs of the completed run, oldest first"
    )


class RunSummary(BaseModel):
    id: str
    status: RunStatus
    reasoner: str
    mode: str
    n_tasks: int
    n_robots: int
    resumes: int
    created_at: Timestamp


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
        "'budget_exhausted' (the run's token budget was spent)",
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


class DecisionOut(BaseModel):
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
    """A revision's link to the run it revised (SPEC 10)."""

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
