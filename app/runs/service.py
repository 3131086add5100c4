"""Run commands and views, as keyword-only functions the routes (and the CLI) call."""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from typing import Any

from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from app.allocation.service import resolve_instance
from app.config import Settings
from app.domain.errors import RunStateConflictError
from app.domain.estimates import RateSource
from app.domain.lifecycle import FINISHED
from app.domain.objective import Objective
from app.domain.problem import Problem
from app.domain.serialize import instance_to_dict
from app.reasoners.factory import check_reasoner
from app.runs import lifecycle, review_gate
from app.runs.lifecycle import EventKind, RunStatus
from app.runs.replay_source import REPLAY, replay_spec, validate_replay
from app.runs.spec import RunOrder, RunSpec, copied_parameters, repeated_parameters
from app.runs.views import require_run
from app.runs.worker import RunWorker
from app.store import chain
from app.store import site_repository as site_repo
from app.store.db import transaction
from app.store.idempotency import Idempotency, run_for_key
from app.store.models import Run, utcnow


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
        check_reasoner(
            spec.reasoner, settings=settings, model=spec.model, temperature=spec.temperature
        )
    run_id = uuid.uuid4().hex
    with transaction(sessions) as session:
        run = insert_run(
            session,
            run_id=run_id,
            spec=spec,
            problem=problem,
            idempotency=idempotency,
            created={"replay_of": spec.replay_of} if spec.replay_of else {},
        )
    worker.submit(run_id)
    return run


def insert_run(
    session: Session,
    *,
    run_id: str,
    spec: RunSpec,
    problem: Problem,
    idempotency: Idempotency | None,
    created: Mapping[str, Any],
    first_event: EventKind = EventKind.CREATED,
    **row: Any,
) -> Run:
    """A queued run's row for `spec` and its first event, whose detail is `created` and
    what the spec shows of itself (RunSpec.created_detail): for a new run (create_run) and
    for a revision (app.plans.revisions, `revised`, with its row's revision columns)."""
    shown = spec.created_detail(problem)  # the instance's size counted once, for both
    return lifecycle.new_run(
        session,
        run_id=run_id,
        request=spec.to_json(),
        reasoner=spec.reasoner,
        mode=spec.mode,
        max_deviation=problem.cap.max_deviation,
        n_tasks=shown["tasks"],
        n_robots=shown["robots"],
        resumes=0,
        cancel_requested=False,
        idempotency_key=idempotency.key if idempotency else None,
        request_digest=idempotency.digest if idempotency else None,
        chain_scheme=chain.SCHEME_V2,
        site=spec.site,
        first_event=first_event,
        created={**created, **shown},
        **row,
    )


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
    instance = resolve_instance(order)
    # An explicit `"max_deviation": null` means no cap; leaving it out means the mode's.
    problem = Problem.build(
        instance,
        order.mode,
        order.max_deviation,
        uncapped="max_deviation" in order.sent and order.max_deviation is None,
        objective=Objective(order.objective, order.min_expected_success),
    )
    scope: dict[str, Any] = {}
    if order.llm_scope is not None:
        scope["llm_scope"] = order.llm_scope
    if order.llm_margin is not None:
        scope["llm_margin"] = float(order.llm_margin)
    spec = RunSpec.for_instance(
        instance,
        **copied_parameters(order),
        mode=problem.mode.value,
        max_deviation=problem.cap.max_deviation,
        cap_explicit="max_deviation" in order.sent,
        reasoner=reasoner,
        token_budget=order.token_budget
        if order.token_budget is not None
        else settings.run_token_budget,
        review=review_gate.policy_for(order.review, instance),
        objective=problem.objective.kind.value,
        min_expected_success=problem.objective.min_expected_success,
        reply_format=settings.llm_reply_format,
        llm_give_up_after=settings.llm_give_up_after,
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
    """docs/estimates.md#using-the-estimates: a run asking for learned (or sampled) rates or
    durations plans with the site's estimates now, its own configured rates the priors; nothing to
    do otherwise."""
    if (source or spec.rates) == RateSource.CONFIGURED and spec.durations == "configured":
        return spec
    as_of = utcnow().isoformat()  # taken before the read: an as_of read later sees as much
    with sessions() as session:
        counts = site_repo.site_counts(session=session, site=spec.site)
    return spec.with_site_estimates(
        counts, strength=settings.prior_strength, as_of=as_of, source=source, only=only
    )


def _sent_for_replay(order: RunOrder) -> dict[str, Any]:
    """What a replay request sent explicitly (each must match the original run), keyed by
    request field, valued as a run spec stores it; omitted fields are copied."""
    values: dict[str, Any] = {}
    named = [f for f in ("scenario", "tasks", "robots") if getattr(order, f) is not None]
    if named:
        values[named[0]] = instance_to_dict(resolve_instance(order))
    return values | repeated_parameters(order)


def resume_run(*, sessions: sessionmaker[Session], worker: RunWorker, run_id: str) -> Run:
    with transaction(sessions) as session:
        run = require_run(session, run_id)
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
        return require_run(session, run_id)


def cancel_run(*, sessions: sessionmaker[Session], worker: RunWorker, run_id: str) -> Run:
    with transaction(sessions) as session:
        # Locked: with several processes, none may claim the run while this decides.
        run = require_run(session, run_id, lock=True)
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
        return require_run(session, run_id)
