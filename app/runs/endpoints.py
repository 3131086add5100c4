"""Durable LTAA runs: create, poll, audit, resume, cancel."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Body, Query, Response, status
from fastapi.responses import StreamingResponse

from app.allocation.schemas import MetricsOut, UsageOut, ViolationOut
from app.allocation.team_schemas import TeamMemberOut
from app.audit import verify
from app.domain.estimates import DurationSource, RateSource
from app.domain.models import Instance
from app.graph.recorder import DecisionRecord
from app.http.deps import ClientDep, SettingsDep, SupervisorDep
from app.http.fields import SiteName
from app.http.idempotency import CREATED_HEADERS, IdempotencyKey, idempotency_of, mark_replayed
from app.http.responses import BODY, CLIENT, SUPERVISOR, errors
from app.reasoners.attribution import Attribution, attempt_attribution, decision_attribution
from app.runs import service, views
from app.runs.deps import RunIdPath, RunsContext, RunsDep
from app.runs.examples import RUN_EXAMPLES
from app.runs.schemas import (
    DEFAULT_PAGE,
    MAX_PAGE,
    DecisionReviewOut,
    ExecutionStateOut,
    Page,
    Progress,
    RunAssignment,
    RunCreated,
    RunOut,
    RunRequest,
    RunStatus,
    RunSummary,
    signoff_out,
)
from app.runs.spec import RunSpec
from app.runs.time_schemas import decision_times
from app.runs.trace import JSONL_RESPONSE, jsonl_trace, verify_out
from app.runs.trace_schemas import AttemptOut, DecisionOut, EventOut, TraceOut, TraceVerifyOut
from app.store.models import Attempt, ExecutionReport

router = APIRouter(prefix="/runs", tags=["runs"])

LOCATION_HEADER: dict[str, Any] = {
    "Location": {"description": "The run: /runs/{id}", "schema": {"type": "string"}}
}


@router.post(
    "",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=RunCreated,
    responses={202: {"headers": CREATED_HEADERS}, **errors(*CLIENT, *BODY, 409, 410)},
)
def create_run(
    caller: ClientDep,
    body: Annotated[RunRequest, Body(openapi_examples=RUN_EXAMPLES)],
    runs: RunsDep,
    settings: SettingsDep,
    response: Response,
    idempotency_key: IdempotencyKey,
) -> RunCreated:
    """Start an LTAA run in the background; poll the Location for progress."""
    run, replayed = service.submit_run(
        sessions=runs.sessions,
        worker=runs.worker,
        settings=settings,
        order=body.to_order(),
        idempotency=idempotency_of(idempotency_key, body),
    )
    response.headers["Location"] = f"/runs/{run.id}"
    mark_replayed(response, replayed)
    # A replay answers as the first request was answered, when the run was just queued.
    return RunCreated(
        id=run.id,
        status=RunStatus.QUEUED if replayed else RunStatus(run.status),
        location=f"/runs/{run.id}",
    )


@router.get("", response_model=list[RunSummary], responses=errors(*CLIENT))
def list_runs(
    caller: ClientDep,
    runs: RunsDep,
    status_: Annotated[RunStatus | None, Query(alias="status")] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=1_000_000_000)] = 0,
    site: Annotated[SiteName | None, Query(description="Only this site's runs")] = None,
) -> list[RunSummary]:
    """List runs, newest first, optionally only those with one status or on one site."""
    where = {} if site is None else {"site": site}
    rows = views.list_run_rows(
        sessions=runs.sessions, status=status_, limit=limit, offset=offset, **where
    )
    return [RunSummary.model_validate(r) for r in rows]


PageOffset = Annotated[
    int, Query(ge=0, le=1_000_000_000, description="Skip this many items (queue order)")
]
PageLimit = Annotated[int, Query(ge=1, le=MAX_PAGE, description="Return at most this many")]


def _team_out(d: DecisionRecord) -> list[TeamMemberOut] | None:
    """docs/allocation.md#teams: a team decision's members, one per unit."""
    return None if not d.team else [TeamMemberOut.model_validate(m) for m in d.team]


def _review_out(review: dict[str, Any] | None) -> DecisionReviewOut | None:
    return None if review is None else DecisionReviewOut.model_validate(review)


def _assignment(view: views.RunView, d: DecisionRecord) -> RunAssignment:
    instance = view.spec.problem.instance
    return RunAssignment(
        task_index=d.task_index,
        task_id=instance.tasks[d.task_index].id,
        task_name=d.task_name,
        robot=instance.robots[d.robot].name,
        success=d.expected_success,
        fallback=d.fallback,
        review=_review_out(d.review),
        pinned=d.task_index in view.pins,
        pinned_from=view.pins.get(d.task_index),
        execution=_execution_out(view.execution.get(d.task_index)),
        team=_team_out(d),
        **decision_times(instance, d),
    )


def _run_head(view: views.RunView, limit: int) -> RunOut:
    """The run's answer without its assignments, which app.runs.pages fills in."""
    run, spec = view.run, view.spec
    return RunOut(
        id=run.id,
        status=RunStatus(run.status),
        reasoner=run.reasoner,
        mode=run.mode,
        max_deviation=run.max_deviation,
        progress=Progress(**view.progress),
        workload=view.workload,
        assignments=[],
        assignments_page=Page(offset=view.offset, limit=limit, total=view.allocated),
        metrics=MetricsOut.from_domain(view.metrics) if view.metrics else None,
        regret=view.regret,
        usage=UsageOut.from_domain(view.usage),
        resumes=run.resumes,
        graph_version=run.graph_version,
        error=run.error,
        revision_of=run.revision_of,
        revision=run.revision,
        superseded_by=run.superseded_by,
        created_at=run.created_at,
        updated_at=run.updated_at,
        finished_at=run.finished_at,
        signoffs=[signoff_out(s) for s in view.signoffs],
        site=run.site,
        rates=RateSource(spec.rates),
        durations=DurationSource(spec.durations),
        schedule_violations=None
        if view.violations is None
        else [ViolationOut.model_validate(v) for v in view.violations],
    )


def _execution_out(report: ExecutionReport | None) -> ExecutionStateOut | None:
    return None if report is None else ExecutionStateOut.model_validate(report)


@router.get("/{run_id}", response_model=RunOut, responses=errors(*CLIENT, 404, 410))
def get_run(
    caller: ClientDep,
    run_id: RunIdPath,
    runs: RunsDep,
    offset: PageOffset = 0,
    limit: PageLimit = DEFAULT_PAGE,
) -> Response:
    """A run's status, progress, workload, a page of its assignments, metrics and usage."""
    return _page_out(runs, run_id, offset, limit)


def _page_out(runs: RunsContext, run_id: str, offset: int, limit: int) -> Response:
    """RunOut's JSON, with the assignments this process rendered before kept as rendered
    (a poll of a long run reads and renders only the decisions stored since the last)."""
    kept = runs.pages.kept(run_id)
    view = views.run_view(
        sessions=runs.sessions,
        run_id=run_id,
        offset=offset,
        limit=limit,
        have=kept.keys(),
        tallies=runs.tallies,
    )
    return runs.pages.response(
        view,
        _run_head(view, limit),
        kept,
        lambda d: _assignment(view, d),
    )


def _attempt_out(a: Attempt, prompts: bool, run_reasoner: str) -> AttemptOut:
    who = attempt_attribution(a.reply_extra, a.reply_model, run_reasoner)
    return AttemptOut(
        attempt=a.attempt,
        tier=a.tier,
        parsed=a.parsed,
        scores=a.scores or {},
        quality=a.quality,
        accepted=a.accepted,
        hard_invalid=a.hard_invalid,
        feedback=a.feedback,
        input_tokens=a.input_tokens,
        output_tokens=a.output_tokens,
        latency_ms=a.latency_ms,
        transport_retries=a.transport_retries,
        model=a.reply_model,
        reasoner=who.reasoner,
        why=who.why,  # type: ignore[arg-type]  # one of the StandIn values, as stored
        replayed_from=(a.reply_extra or {}).get("replayed_from"),
        original_model=(a.reply_extra or {}).get("original_model"),
        system_prompt=a.system_prompt if prompts else None,
        user_prompt=a.user_prompt if prompts else None,
        reply=a.reply_text if prompts else None,
    )


@router.get(
    "/{run_id}/trace",
    response_model=TraceOut,
    responses={**errors(*SUPERVISOR, 404, 410), 200: JSONL_RESPONSE},
)
def get_trace(
    caller: SupervisorDep,
    run_id: RunIdPath,
    runs: RunsDep,
    include: Annotated[Literal["prompts"] | None, Query()] = None,
    format_: Annotated[
        Literal["json", "jsonl"],
        Query(
            alias="format",
            description="jsonl: stream the whole audit record (with prompts) as JSON lines",
        ),
    ] = "json",
    offset: PageOffset = 0,
    limit: PageLimit = DEFAULT_PAGE,
) -> TraceOut | StreamingResponse:
    """For supervisors: run events and every decision with its validated attempts."""
    if format_ == "jsonl":
        return jsonl_trace(sessions=runs.sessions, run_id=run_id)
    trace = views.run_trace(sessions=runs.sessions, run_id=run_id, offset=offset, limit=limit)
    spec = RunSpec.from_json(trace.run.request)
    instance = spec.problem.instance
    names = [r.name for r in instance.robots]
    prompts = include == "prompts"
    return TraceOut(
        id=trace.run.id,
        status=RunStatus(trace.run.status),
        reasoner=trace.run.reasoner,
        mode=trace.run.mode,
        max_deviation=trace.run.max_deviation,
        robots=names,
        events=[
            EventOut(seq=e.seq, kind=e.kind, detail=e.detail, at=e.created_at) for e in trace.events
        ],
        decisions=[
            _decision_out(
                d,
                trace.attempts.get(d.task_index, []),
                instance=instance,
                names=names,
                prompts=prompts,
                run_reasoner=trace.run.reasoner,
                pins=trace.pins,
            )
            for d in trace.decisions
        ],
        decisions_page=Page(offset=offset, limit=limit, total=trace.total),
    )


def _decision_out(
    d: DecisionRecord,
    attempts: list[Attempt],
    *,
    instance: Instance,
    names: list[str],
    prompts: bool,
    run_reasoner: str,
    pins: dict[int, str | None],
) -> DecisionOut:
    outs = [_attempt_out(a, prompts, run_reasoner) for a in attempts]
    accepted = next((a for a in reversed(outs) if a.accepted), None)
    who = decision_attribution(
        d.fallback, Attribution(accepted.reasoner, accepted.why) if accepted else None
    )
    return DecisionOut(
        task_index=d.task_index,
        task_id=instance.tasks[d.task_index].id,
        task_name=d.task_name,
        robot=names[d.robot],
        expected_success=d.expected_success,
        phase=d.phase,
        loads_before=d.loads_before,
        loads_after=d.loads_after,
        balance_before=d.balance_before,
        balance_after=d.balance_after,
        severity_after=d.severity_after,
        reasoning=d.reasoning,
        confidence=d.confidence,
        tradeoff=d.tradeoff,
        quality=d.quality,
        fallback=d.fallback,
        failure_log=d.failure_log,
        regret=d.regret,
        reasoner=who.reasoner,
        why=who.why,  # type: ignore[arg-type]  # one of the StandIn values
        review=_review_out(d.review),
        pinned=d.task_index in pins,
        pinned_from=pins.get(d.task_index),
        attempts=outs,
        team=_team_out(d),
        **decision_times(instance, d),
    )


@router.get(
    "/{run_id}/trace/verify", response_model=TraceVerifyOut, responses=errors(*SUPERVISOR, 404, 410)
)
def verify_trace(caller: SupervisorDep, run_id: RunIdPath, runs: RunsDep) -> TraceVerifyOut:
    """For supervisors: recompute the run's hash chains; ok, or the first broken link."""
    return verify_out(
        verify.verify_trace(sessions=runs.sessions, run_id=run_id, keys=runs.worker.signing_keys)
    )


@router.post(
    "/{run_id}/resume",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=RunSummary,
    responses={202: {"headers": LOCATION_HEADER}, **errors(*SUPERVISOR, 404, 409, 410)},
)
def resume_run(
    caller: SupervisorDep, run_id: RunIdPath, runs: RunsDep, response: Response
) -> RunSummary:
    """For supervisors: resume an interrupted (or failed) run from its last checkpoint; poll
    the Location for its progress."""
    run = service.resume_run(sessions=runs.sessions, worker=runs.worker, run_id=run_id)
    response.headers["Location"] = f"/runs/{run.id}"
    return RunSummary.model_validate(run)


@router.post(
    "/{run_id}/cancel", response_model=RunOut, responses=errors(*SUPERVISOR, 404, 409, 410)
)
def cancel_run(caller: SupervisorDep, run_id: RunIdPath, runs: RunsDep) -> Response:
    """For supervisors: cancel a queued or running run; a running one stops within one node."""
    service.cancel_run(sessions=runs.sessions, worker=runs.worker, run_id=run_id)
    return _page_out(runs, run_id, 0, DEFAULT_PAGE)
