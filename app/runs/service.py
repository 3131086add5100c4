"""Run commands and views, as keyword-only functions the routes (and the CLI) call."""

from __future__ import annotations

import statistics
import uuid
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, defer, sessionmaker

from app.audit.signoffs import SignOff, signoffs
from app.config import Settings
from app.domain.catalog import instance_of
from app.domain.errors import RunStateConflictError
from app.domain.estimates import RateSource
from app.domain.lifecycle import FINISHED
from app.domain.metrics import Metrics, compute_metrics
from app.domain.phases import detect_phase
from app.domain.problem import Problem
from app.domain.serialize import instance_to_dict
from app.domain.usage import Usage
from app.graph.recorder import DecisionRecord
from app.reasoners.base import close_reasoner
from app.reasoners.factory import make_reasoner
from app.runs import lifecycle, records, review_gate
from app.runs.idempotency import Idempotency, run_for_key
from app.runs.lifecycle import EventKind, RunStatus
from app.runs.replay import REPLAY, replay_spec, validate_replay
from app.runs.spec import LruCache, RunOrder, RunSpec
from app.runs.worker import RunWorker
from app.store import chain, run_totals
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store import site_repository as site_repo
from app.store.db import transaction
from app.store.models import Attempt, ExecutionReport, Run, RunEvent, utcnow
from app.store.tombstones import missing_run


def create_run(
    *,
    sessions: sessionmaker[Session],
    worker: RunWorker,
    settings: Settings,
    spec: RunSpec,
    idempotency: Idempotency | None = None,
) -> Run:
    """Validate everything first, so a bad request never leaves a half-written run."""
    problem = spec.problem  # raises DomainError for an infeasible cap, bad instance...
    # A replay names a completed run and copies its parameters; nothing else names a run.
    validate_replay(sessions=sessions, spec=spec)
    if spec.replay_of is None:  # a replay's reasoner is built from the record, at run time
        # Raises for an unknown reasoner or a missing key; the run builds its own later.
        close_reasoner(
            make_reasoner(
                spec.reasoner, settings=settings, model=spec.model, temperature=spec.temperature
            )
        )
    run_id = uuid.uuid4().hex
    with transaction(sessions) as session:
        run = lifecycle.new_run(
            session,
            run_id=run_id,
            request=spec.to_json(),
            reasoner=spec.reasoner,
            mode=spec.mode,
            max_deviation=problem.cap.max_deviation,
            n_tasks=problem.instance.n_tasks,
            n_robots=problem.instance.n_robots,
            resumes=0,
            cancel_requested=False,
            idempotency_key=idempotency.key if idempotency else None,
            chain_scheme=chain.SCHEME_V2,
            request_digest=idempotency.digest if idempotency else None,
            site=spec.site,
            created={
                "reasoner": spec.reasoner,
                "mode": spec.mode,
                "tasks": problem.instance.n_tasks,
                "robots": problem.instance.n_robots,
                "max_deviation": problem.cap.max_deviation,
                **({"replay_of": spec.replay_of} if spec.replay_of else {}),
                **spec.site_detail(),
            },
        )
    worker.submit(run_id)
    return run


def create_or_replay_run(
    *,
    sessions: sessionmaker[Session],
    worker: RunWorker,
    settings: Settings,
    spec: RunSpec,
    idempotency: Idempotency | None,
) -> tuple[Run, bool]:
    """Create a run, under an Idempotency-Key if the request sent one: (the run, whether an
    earlier request with the same key and body created it). The same key with another body
    is a 409."""
    if idempotency is None:
        return create_run(sessions=sessions, worker=worker, settings=settings, spec=spec), False
    try:
        return create_run(
            sessions=sessions, worker=worker, settings=settings, spec=spec, idempotency=idempotency
        ), False
    except IntegrityError:
        # No look-up first: the unique index on the key is the one arbiter, so a retry after
        # the first request ended and two requests at once end the same way. The insert
        # rolled back whole; the run that holds the key answers this request too.
        earlier = run_for_key(sessions=sessions, idempotency=idempotency)
        if earlier is None:
            raise  # the key was free: a different constraint failed
        return earlier, True


def submit_run(
    *,
    sessions: sessionmaker[Session],
    worker: RunWorker,
    settings: Settings,
    order: RunOrder,
    idempotency: Idempotency | None,
) -> tuple[Run, bool]:
    """POST /runs: a request to a stored, queued run, in one call. (The run, whether an
    earlier request with the same Idempotency-Key created it.) Everything is checked before
    anything is written: the instance, the cap, a replay against its source, the reasoner,
    the review policy."""
    spec = spec_for(order, sessions=sessions, settings=settings)
    return create_or_replay_run(
        sessions=sessions, worker=worker, settings=settings, spec=spec, idempotency=idempotency
    )


def spec_for(order: RunOrder, *, sessions: sessionmaker[Session], settings: Settings) -> RunSpec:
    """What a run will do: a replay copies its source; any other run takes the order's
    instance and parameters, with the server's defaults where the order left them out."""
    reasoner = order.reasoner or settings.default_reasoner
    if reasoner == REPLAY or order.replay_of is not None:
        return replay_spec(
            sessions=sessions,
            reasoner=reasoner,
            replay_of=order.replay_of,
            sent=_sent_for_replay(order),
        )
    instance = instance_of(order.scenario, order.tasks, order.robots)
    # An explicit `"max_deviation": null` means no cap; leaving it out means the mode's.
    problem = Problem.build(
        instance,
        order.mode,
        order.max_deviation,
        uncapped="max_deviation" in order.sent and order.max_deviation is None,
    )
    scope: dict[str, Any] = {}
    if order.llm_scope is not None:
        scope["llm_scope"] = order.llm_scope
    if order.llm_margin is not None:
        scope["llm_margin"] = float(order.llm_margin)
    spec = RunSpec.for_instance(
        instance,
        mode=problem.mode.value,
        max_deviation=problem.cap.max_deviation,
        cap_explicit="max_deviation" in order.sent,
        seed=order.seed,
        reasoner=reasoner,
        quality_threshold=order.quality_threshold,
        max_retries=order.max_retries,
        model=order.model,
        temperature=order.temperature,
        guidance=order.guidance,
        token_budget=order.token_budget
        if order.token_budget is not None
        else settings.run_token_budget,
        review=review_gate.policy_for(order.review, instance),
        site=order.site,
        rates=order.rates.value,
        durations=order.durations.value,
        **scope,
    )
    return learned_spec(spec, sessions=sessions, settings=settings)


def learned_spec(
    spec: RunSpec,
    *,
    sessions: sessionmaker[Session],
    settings: Settings,
    source: RateSource | None = None,
    only: list[str] | None = None,
) -> RunSpec:
    """SPEC 17: a run asking for learned (or sampled) rates or durations plans with the
    site's estimates now, its own configured rates the priors; nothing to do otherwise."""
    if (source or spec.rates) == RateSource.CONFIGURED and spec.durations == "configured":
        return spec
    as_of = utcnow().isoformat()  # taken before the read: an as_of read later sees as much
    with sessions() as session:
        counts = site_repo.site_counts(session=session, site=spec.site)
    return spec.with_site_estimates(
        counts, strength=settings.prior_strength, as_of=as_of, source=source, only=only
    )


# The fields a replay may repeat (each must equal its source's), as a run spec stores them.
_REPEATABLE = (
    "max_deviation",
    "quality_threshold",
    "max_retries",
    "guidance",
    "seed",
    "model",
    "temperature",
    "token_budget",
    "llm_scope",
    "llm_margin",
    "review",
    "site",
    "rates",
    "durations",
)


def _sent_for_replay(order: RunOrder) -> dict[str, Any]:
    """What a replay request sent explicitly (each must match the original run), keyed by
    request field, valued as a run spec stores it; omitted fields are copied."""
    values: dict[str, Any] = {}
    named = [f for f in ("scenario", "tasks", "robots") if getattr(order, f) is not None]
    if named:
        instance = instance_of(order.scenario, order.tasks, order.robots)
        values[named[0]] = instance_to_dict(instance)
    if "mode" in order.sent:
        values["mode"] = order.mode.value
    for name in _REPEATABLE:
        if name in order.sent:
            values[name] = getattr(order, name)
    return values


def _require(session: Session, run_id: str, *, lock: bool = False) -> Run:
    run = repo.get_run(session=session, run_id=run_id, for_update=lock)
    if run is None:
        raise missing_run(session, run_id)
    return run


def resume_run(*, sessions: sessionmaker[Session], worker: RunWorker, run_id: str) -> Run:
    with transaction(sessions) as session:
        run = _require(session, run_id)
        if run.status == RunStatus.COMPLETED:
            raise RunStateConflictError(
                run_id, run.status, "resume", "A completed run has nothing left to do."
            )
        if run.status == RunStatus.CANCELLED:
            raise RunStateConflictError(run_id, run.status, "resume", "Create a new run instead.")
        if run.status == RunStatus.AWAITING_REVIEW:
            raise RunStateConflictError(
                run_id,
                run.status,
                "resume",
                "It waits for a supervisor: resolve its review (GET /reviews, "
                "POST /runs/{id}/reviews/{task_index}).",
            )
        if run.status == RunStatus.SUPERSEDED:
            raise RunStateConflictError(
                run_id,
                run.status,
                "resume",
                f"A revision replaced it: run '{run.superseded_by}' (GET /runs/{{id}}/revisions).",
            )
        if run.status in (RunStatus.QUEUED, RunStatus.RUNNING) or worker.is_active(run_id):
            raise RunStateConflictError(run_id, run.status, "resume", "It is already running.")
        if run.status in (RunStatus.FAILED, RunStatus.BLOCKED):
            # Its error stays readable until a worker takes it up again (a blocked run is
            # blocked again, with the same error, if this server's graph version differs).
            lifecycle.move(session, run, RunStatus.INTERRUPTED, error=run.error)
    worker.submit(run_id)
    with sessions() as session:
        return _require(session, run_id)


def cancel_run(*, sessions: sessionmaker[Session], worker: RunWorker, run_id: str) -> Run:
    with transaction(sessions) as session:
        # Locked: with several processes, none may claim the run while this decides.
        run = _require(session, run_id, lock=True)
        if run.status in FINISHED:
            raise RunStateConflictError(run_id, run.status, "cancel", "It has already ended.")
        run.cancel_requested = True
        if run.status == RunStatus.AWAITING_REVIEW:
            # Nobody holds it: close its review, then cancel (the last event is `cancelled`).
            review_gate.close_pending(session, run_id, "the run was cancelled")
            lifecycle.move(
                session,
                run,
                RunStatus.CANCELLED,
                event=EventKind.CANCELLED,
                detail={"reason": "cancel requested while awaiting review"},
            )
        elif not worker.is_active(run_id):
            lifecycle.move(
                session,
                run,
                RunStatus.CANCELLED,
                event=EventKind.CANCELLED,
                detail={"reason": "cancel requested before it ran"},
            )
    worker.cancel(run_id)
    with sessions() as session:
        return _require(session, run_id)


@dataclass
class RunView:
    """A run with one page of its decisions; the totals (progress, workload, regret, metrics)
    cover every decision, so a long run answers a poll without sending them all."""

    run: Run
    spec: RunSpec
    decisions: list[DecisionRecord]
    offset: int
    allocated: int
    workload: dict[str, int]
    regret: float | None
    usage: Usage
    metrics: Metrics | None
    signoffs: list[SignOff] = field(default_factory=list)
    execution: dict[int, ExecutionReport] = field(default_factory=dict)
    # Task index -> the parent decision's chain hash, for this page's pinned decisions.
    pins: dict[int, str | None] = field(default_factory=dict)

    @property
    def progress(self) -> dict[str, Any]:
        return {
            "allocated": self.allocated,
            "total": self.run.n_tasks,
            "phase": detect_phase(min(self.allocated, self.run.n_tasks), self.run.n_tasks).value,
        }


_SPECS: LruCache[RunSpec] = LruCache(64)
_METRICS: LruCache[Metrics] = LruCache(256)


def run_view(
    *, sessions: sessionmaker[Session], run_id: str, offset: int = 0, limit: int | None = None
) -> RunView:
    """The run with its decisions from the offset-th, at most limit of them (None: all)."""
    with sessions() as session:
        # The request (a 10,000-task instance is a megabyte of JSON) is read and parsed once
        # per run: it never changes, and a poll every 0.5 s parsed it every time.
        run = session.scalar(select(Run).options(defer(Run.request)).where(Run.id == run_id))
        if run is None:
            raise missing_run(session, run_id)
        spec = _SPECS.get_or_load(
            run_id, lambda: RunSpec.from_json(_require(session, run_id).request)
        )
        totals = run_totals.decision_totals(session=session, run_id=run_id)
        rows = run_totals.decision_page(session=session, run_id=run_id, offset=offset, limit=limit)
        decisions = [records.decision_record(d) for d in rows]
        pins = pins_of(rows)
        usage = records.usage_of_totals(run_totals.reply_totals(session=session, run_id=run_id))
        signed = signoffs(session=session, run_id=run_id)
        execution = {
            r.task_index: r for r in repo.execution_reports(session=session, run_id=run_id)
        }
        completed = run.status == RunStatus.COMPLETED and totals.allocated == run.n_tasks
        # Every decision's robot only once the run is complete, for its metrics.
        outcomes = (
            decision_repo.decision_outcomes(session=session, run_id=run_id)
            if completed and _METRICS.get(run_id) is None
            else []
        )
    names = [r["name"] for r in spec.instance_data["robots"]]
    workload = dict.fromkeys(names, 0)
    for robot, n in sorted(totals.by_robot.items()):
        workload[names[robot]] += n
    metrics = _METRICS.get(run_id) if completed else None
    if completed and metrics is None:
        problem = spec.problem
        metrics = compute_metrics(
            problem.instance,
            [o.robot for o in outcomes],
            seed=spec.seed,
            scope=problem.balance_scope,
        )
        if problem.pinned:
            # A pin keeps the success it was decided with, whatever set_rates changed.
            metrics = replace(
                metrics,
                expected_success=statistics.fmean(o.expected_success for o in outcomes),
            )
        _METRICS.put(run_id, metrics)  # a completed run's decisions never change
    return RunView(
        run=run,
        spec=spec,
        decisions=decisions,
        offset=offset,
        allocated=totals.allocated,
        workload=workload,
        regret=totals.regret,
        usage=usage,
        metrics=metrics,
        execution=execution,
        pins=pins,
        signoffs=signed,
    )


def run_row(*, sessions: sessionmaker[Session], run_id: str) -> Run:
    with sessions() as session:
        return _require(session, run_id)


def list_run_rows(
    *, sessions: sessionmaker[Session], status: str | None, limit: int, offset: int, **where: str
) -> list[Run]:
    with sessions() as session:
        return repo.list_runs(session=session, status=status, limit=limit, offset=offset, **where)


@dataclass
class Trace:
    """A run's events with one page of its decisions (and their attempts)."""

    run: Run
    events: list[RunEvent]
    decisions: list[DecisionRecord]
    attempts: dict[int, list[Attempt]]
    total: int
    # A revision's decisions kept from its parent (SPEC 10): task index -> the parent
    # decision's chain hash (`pinned_from`).
    pins: dict[int, str | None] = field(default_factory=dict)


def run_trace(
    *, sessions: sessionmaker[Session], run_id: str, offset: int = 0, limit: int | None = None
) -> Trace:
    with sessions() as session:
        run = _require(session, run_id)
        page = decision_repo.decisions_slice(
            session=session, run_id=run_id, offset=offset, limit=limit
        )
        attempts = (
            decision_repo.attempts_of_tasks(
                session=session, run_id=run_id, first=page[0].task_index, last=page[-1].task_index
            )
            if page
            else {}
        )
        return Trace(
            run=run,
            events=repo.events(session=session, run_id=run_id),
            decisions=[records.decision_record(d) for d in page],
            attempts=attempts,
            total=decision_repo.decision_count(session=session, run_id=run_id),
            pins=pins_of(page),
        )


def pins_of(rows: Iterable[Any]) -> dict[int, str | None]:
    """Which of these decision rows a revision kept from its parent, with the parent
    decision's chain hash."""
    return {d.task_index: d.pinned_from for d in rows if d.pinned}
