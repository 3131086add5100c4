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
from app.http.answers import from_row
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
from app.runs.time_schemas import DecisionTimes, decision_times
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


def _times(instance: Instance, d: DecisionRecord) -> dict[str, Any]:
    """The DecisionTimes fields, all given: an untimed decision's are absent (None), even
    where the record holds a zone, as decision_times has them."""
    return {**dict.fromkeys(DecisionTimes.model_fields), **decision_times(instance, d)}


def _assignment(view: views.RunView, d: DecisionRecord) -> RunAssignment:
    # From the record: task_index, task_name, fallback. The rest differs in shape: the task's
    # id and the robot's name resolved against the instance (the record's robot is an
    # index; a task id keeps its int or str type there), `success` is the record's
    # expected_success, the pins, the execution report and the times come from the view.
    instance = view.spec.problem.instance
    return from_row(
        RunAssignment,
        d,
        task_id=instance.tasks[d.task_index].id,
        robot=instance.robots[d.robot].name,
        success=d.expected_success,
        review=_review_out(d.review),
        pinned=d.task_index in view.pins,
        pinned_from=view.pins.get(d.task_index),
        execution=_execution_out(view.execution.get(d.task_index)),
        team=_team_out(d),
        **_times(instance, d),
    )


def _run_head(view: views.RunView, limit: int) -> RunOut:
    """The run's answer without its assignments, which app.runs.pages fills in."""
    # From the run's row: id, status, reasoner, mode, max_deviation, resumes, graph_version,
    # error, the lineage (revision_of, revision, superseded_by), the times and the site.
    # What the row does not hold comes from the view: progress, workload, the page, the
    # metrics, regret and usage, the sign-offs, the violations, and the rates and durations
    # its spec planned with.
    return from_row(
        RunOut,
        view.run,
        progress=Progress(**view.progress),
        workload=view.workload,
        assignments=[],
        assignments_page=Page(offset=view.offset, limit=limit, total=view.allocated),
        metrics=MetricsOut.from_domain(view.metrics) if view.metrics else None,
        regret=view.regret,
        usage=UsageOut.from_domain(view.usage),
        signoffs=[signoff_out(s) for s in view.signoffs],
        rates=RateSource(view.spec.rates),
        durations=DurationSource(view.spec.durations),
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
    # From the attempt's row: attempt, tier, parsed, quality, accepted, hard_invalid,
    # feedback, the tokens, latency_ms, transport_retries. Differing: the row's reply_*
    # columns answer as model and reply, who wrote it is read from reply_extra, scores may
    # be null in the row, and the prompts are answered only with ?include=prompts.
    who = attempt_attribution(a.reply_extra, a.reply_model, run_reasoner)
    extra = a.reply_extra or {}
    return from_row(
        AttemptOut,
        a,
        scores=a.scores or {},
        model=a.reply_model,
        reasoner=who.reasoner,
        why=who.why,
        replayed_from=extra.get("replayed_from"),
        original_model=extra.get("original_model"),
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
    # id, status, reasoner, mode and max_deviation from the run's row; an event's row answers
    # its created_at as `at`.
    return from_row(
        TraceOut,
        trace.run,
        robots=names,
        events=[from_row(EventOut, e, at=e.created_at) for e in trace.events],
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
    # From the record: the task's index and name, expected_success, phase, the loads and
    # balances, severity, reasoning, confidence, trade-off, quality, fallback, failure_log,
    # regret. Differing: the task id and robot name resolved against the instance, who
    # decided (the accepted attempt's attribution, or the fallback), the pins, the attempts
    # (the record counts them; the answer lists them) and the times.
    return from_row(
        DecisionOut,
        d,
        task_id=instance.tasks[d.task_index].id,
        robot=names[d.robot],
        reasoner=who.reasoner,
        why=who.why,
        review=_review_out(d.review),
        pinned=d.task_index in pins,
        pinned_from=pins.get(d.task_index),
        attempts=outs,
        team=_team_out(d),
        **_times(instance, d),
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
