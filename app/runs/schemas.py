"""Bodies of the /runs endpoints: the durable LTAA runs (their trace: app.runs.trace_schemas)."""

from __future__ import annotations

from typing import Any, Literal, cast

from pydantic import BaseModel, ConfigDict, Field
from pydantic.config import JsonDict

from app.allocation.schemas import (
    CUSTOM_FORM,
    MAX_SEED,
    SCENARIO_FORM,
    InstanceRequest,
    MetricsOut,
    Name,
    TaskId,
    UsageOut,
    ViolationOut,
    absent,
    present,
)
from app.allocation.team_schemas import MEMBERS_FIELD, TeamMemberOut
from app.audit.signoffs import SignOff
from app.domain.estimates import DEFAULT_SITE, DurationSource, RateSource
from app.domain.lifecycle import RunStatus
from app.domain.objective import ObjectiveKind
from app.domain.review import ReviewAction, ReviewOn
from app.http.answers import from_row
from app.http.times import Timestamp
from app.runs.spec import ORDER_INSTANCE_FIELDS, RUN_PARAMETERS, RunOrder
from app.runs.time_schemas import DecisionTimes

StandIn = Literal["clear-cut", "budget_exhausted", "gave_up", "fallback"]
# Run ids are uuid4 hex; the pattern is looser on purpose, and only keeps out what a
# database may refuse in a query (PostgreSQL rejects a NUL character with an error, a 500).
RUN_ID_PATTERN = r"^[A-Za-z0-9_-]+$"


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
    """Which decisions wait for a supervisor (docs/reviews.md#which-decisions-wait-for-review). A
    decision needs review when any listed condition holds; the run pauses before the decision is
    stored."""

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


# A run has five shapes, each for its reader: RunRequest (what a client posts, with its
# OpenAPI forms), RunOrder (that body as the run service takes it, nothing resolved:
# app.runs.spec), RunSpec (the order resolved and frozen, stored as the run's request and
# replayed by the worker on every resume), the Run row (app.store.models: status, lease,
# lineage, chain) and RunOut (the answer: the row with its views, read with
# from_attributes); RunSummary is the row alone, in a list.
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
    site: Name = Field(
        DEFAULT_SITE,
        description="The site the run plans for (docs/estimates.md#sites): its robots are "
        "(site, name), its "
        "execution reports feed the site's estimates (GET /sites/{site}/estimates)",
    )
    rates: RateSource = Field(
        RateSource.CONFIGURED,
        description="'configured' (default: the rates sent), 'learned' (the site's posterior "
        "means, the rates sent as priors) or 'sampled' (one draw from each posterior: "
        "explores). The numbers planned with are in the run's first event",
    )
    durations: DurationSource = Field(
        DurationSource.CONFIGURED,
        description="'configured' (default) or 'learned' (the site's observed durations, "
        "the tasks' configured ones as priors; only timed instances have any)",
    )
    objective: ObjectiveKind = Field(
        ObjectiveKind.SUCCESS_THEN_MAKESPAN,
        description="Timed instances (docs/api.md#plans-in-time): 'success_then_makespan' "
        "(default) or "
        "'makespan'; the graph decides in time order either way, and the objective is "
        "what guidance optimises and the run records",
    )
    min_expected_success: float = Field(
        0.0, ge=0, le=1, strict=True, allow_inf_nan=False, description="With 'makespan' only"
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

    def to_order(self) -> RunOrder:
        """The request as the run service takes it (app.runs.service.submit_run)."""
        sent_as_is = {
            name: getattr(self, name)
            for name in (*ORDER_INSTANCE_FIELDS, *(p.name for p in RUN_PARAMETERS))
            if name not in ("tasks", "robots", "review")
        }
        return RunOrder(
            **sent_as_is,
            tasks=None if self.tasks is None else tuple(t.to_domain() for t in self.tasks),
            robots=None if self.robots is None else tuple(r.to_domain() for r in self.robots),
            review=None if self.review is None else self.review.model_dump(mode="json"),
            sent=frozenset(self.model_fields_set),
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
    """A supervisor's review of a decision (docs/reviews.md#resolving-a-review); covered by the
    decision's chain hash."""

    action: ReviewAction
    reviewer: str = Field(description="The resolving API key's name")
    reason: str | None
    at: Timestamp
    triggers: list[str]
    overridden_from: str | None = Field(
        None, description="override: the robot the run had proposed (a team: its first member)"
    )
    overridden_from_team: list[TeamMemberOut] | None = Field(
        None,
        description="override of a team decision: the team the run had proposed, in unit order "
        "(docs/reviews.md#reviews-of-team-decisions)",
        exclude_if=lambda members: members is None,
    )


# A task's latest execution report, read from its row (app.store.models.ExecutionReport).
# (A comment, not a docstring: a docstring would become the schema's OpenAPI description.)
class ExecutionStateOut(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    state: Literal["started", "done", "failed"]
    started_at: Timestamp | None
    ended_at: Timestamp | None


# A client's shape of a decision: names, success, pins and the execution report, without
# the ledger and attempts DecisionOut has (why four shapes: app.graph.recorder.DecisionRecord).
class RunAssignment(DecisionTimes):
    task_index: int
    task_id: int | str
    task_name: str
    robot: str
    success: float
    fallback: bool
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


# The answer of GET /runs/{id}: the Run row and its views (why five shapes: RunRequest).
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
    site: str = Field(
        DEFAULT_SITE, description="The site the run plans for (docs/estimates.md#sites)"
    )
    rates: RateSource = Field(
        RateSource.CONFIGURED,
        description="Which success rates it plans with (docs/estimates.md#using-the-estimates)",
    )
    durations: DurationSource = DurationSource.CONFIGURED
    schedule_violations: list[ViolationOut] | None = Field(
        None,
        description="A completed timed run: the rules its plan breaks (e.g. a deadline no "
        "robot could meet, a task added by a revision included), as POST /allocate reports "
        "them; empty when it breaks none",
        exclude_if=lambda v: v is None,
    )


# A run in a list, read from its row (app.store.models.Run) alone; why a run has five other
# shapes: RunRequest.
class RunSummary(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: str
    status: RunStatus
    reasoner: str
    mode: str
    n_tasks: int
    n_robots: int
    resumes: int
    created_at: Timestamp
    site: str = DEFAULT_SITE


def signoff_out(signed: SignOff) -> SignOffOut:
    # signer, at and statement as recorded; the heads a dict that may lack a chain's.
    heads = SignedHeadsOut(
        decisions=signed.heads.get("decisions"), events=signed.heads.get("events")
    )
    return from_row(SignOffOut, signed, heads=heads)
