"""The graph's records as the store's rows, both ways.

The store takes and returns plain column values so that it never depends on the graph or
the reasoners; this module is the one place that knows how a record maps to its columns.

Why a decision keeps four shapes: `DecisionRecord` is what the graph produces (it may not
import the store), the `Decision` row is what the store keeps (with the chain hash and
the columns the record's time lines are flattened into), and the answers differ on
purpose: `DecisionOut` (the supervisors' trace, with attempts and the ledger) and
`RunAssignment` (a client's page of a run, names resolved against the instance). Every
answer is read from its record or row with `from_attributes` (app.http.answers.from_row,
in app.runs.endpoints), given beside it only the fields whose shape differs: the names
the record's indices resolve to against the instance, who decided, the pins, the times.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import fields
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from app.domain.lifecycle import EventKind
from app.domain.problem import Problem
from app.domain.usage import ReplyUsage, Usage
from app.graph.recorder import AttemptRecord, DecisionRecord
from app.reasoners.base import ReasonerReply
from app.runs import lifecycle
from app.solvers.timed_guidance import GuidancePlan, guided_problem, plan_guidance
from app.store import decision_repository as decision_repo
from app.store.db import transaction
from app.store.models import Attempt, Decision, RunEvent

_DECISION_FIELDS = tuple(f.name for f in fields(DecisionRecord))


def decision_values(record: DecisionRecord) -> dict[str, Any]:
    """A decision's column values, without run_id, chain_hash and created_at (the store's).
    Shallow (lists copied): dataclasses.asdict's deep copy was a tenth of a recorder write."""
    values = {name: getattr(record, name) for name in _DECISION_FIELDS}
    for name in ("failure_log", "loads_before", "loads_after"):
        values[name] = list(values[name])
    values["task_id"] = str(record.task_id)
    return values


def attempt_values(record: AttemptRecord) -> dict[str, Any]:
    """An attempt's column values, keys included, without run_id and created_at."""
    reply = record.reply
    return {
        "task_index": record.task_index,
        "attempt": record.attempt,
        "tier": record.tier,
        "system_prompt": record.system_prompt,
        "user_prompt": record.user_prompt,
        "reply_text": reply.text if reply else None,
        "reply_model": reply.model if reply else None,
        "input_tokens": reply.input_tokens if reply else 0,
        "output_tokens": reply.output_tokens if reply else 0,
        "latency_ms": reply.latency_ms if reply else 0.0,
        "transport_retries": reply.transport_retries if reply else 0,
        "reply_extra": dict(reply.extra) if reply else {},
        "parsed": record.parsed,
        "scores": record.scores,
        "quality": record.quality,
        "accepted": record.accepted,
        "hard_invalid": record.hard_invalid,
        "feedback": record.feedback,
    }


def attempt_record(row: Attempt) -> AttemptRecord:
    reply = None
    if row.reply_text is not None:
        reply = ReasonerReply(
            text=row.reply_text,
            input_tokens=row.input_tokens,
            output_tokens=row.output_tokens,
            latency_ms=row.latency_ms,
            model=row.reply_model,
            transport_retries=row.transport_retries,
            extra=dict(row.reply_extra or {}),
        )
    return AttemptRecord(
        task_index=row.task_index,
        attempt=row.attempt,
        tier=row.tier,
        system_prompt=row.system_prompt,
        user_prompt=row.user_prompt,
        reply=reply,
        parsed=row.parsed,
        scores=dict(row.scores or {}),
        quality=row.quality,
        accepted=row.accepted,
        hard_invalid=row.hard_invalid,
        feedback=row.feedback,
    )


def decision_record(row: Decision) -> DecisionRecord:
    fields = DecisionRecord.__dataclass_fields__
    return DecisionRecord(**{name: getattr(row, name) for name in fields})


def usage_of(rows: Iterable[Any]) -> Usage:
    """Usage of stored attempt rows (or of repository.reply_costs rows), by the one rule of
    app.domain.usage."""
    return Usage.from_replies(
        ReplyUsage(
            r.reply_model, r.input_tokens, r.output_tokens, r.transport_retries, r.latency_ms
        )
        for r in rows
    )


def usage_of_totals(rows: Iterable[Any]) -> Usage:
    """Usage from app.store.run_totals.reply_totals rows (one per reply model, summed): the
    rule of app.domain.usage, applied to sums: replies that name a model are the calls."""
    billed = [r for r in rows if r[0] is not None]
    return Usage(
        llm_calls=sum(int(r[1]) for r in billed),
        input_tokens=sum(int(r[2]) for r in billed),
        output_tokens=sum(int(r[3]) for r in billed),
        transport_retries=sum(int(r[4]) for r in billed),
        latency_ms=sum((float(r[5]) for r in billed), 0.0),
    )


# -- a guided timed run's plan (app.solvers.timed_guidance) ----------------------------------


def stored_plan(session: Session, run_id: str) -> GuidancePlan | None:
    """The guidance plan the run recorded as its `guidance_planned` event (None: not yet)."""
    detail = session.scalar(
        select(RunEvent.detail)
        .where(RunEvent.run_id == run_id, RunEvent.kind == EventKind.GUIDANCE_PLANNED.value)
        .order_by(RunEvent.seq)
        .limit(1)
    )
    return GuidancePlan.from_json(detail) if detail is not None else None


def run_problem(session: Session, run_id: str, problem: Problem, guidance: str | None) -> Problem:
    """The problem a run decides: a guided timed run's in its stored plan's order."""
    if guidance != "optimizer" or not problem.instance.timed:
        return problem
    plan = stored_plan(session, run_id)
    return guided_problem(problem, plan) if plan is not None else problem


def guidance_plan(
    sessions: sessionmaker[Session],
    run_id: str,
    problem: Problem,
    guidance: str | None,
    replay_of: str | None = None,
) -> GuidancePlan | None:
    """The plan a guided timed run follows (None: not one): the stored one on resume; at
    the start the original's for a replay, else solved now and recorded before the first
    decision, so a resume after a crash never solves again (CP-SAT at a wall-clock limit
    may return another plan)."""
    if guidance != "optimizer" or not problem.instance.timed:
        return None
    with sessions() as session:
        plan = stored_plan(session, run_id)
        if plan is not None:
            return plan
        if decision_repo.decision_count(session=session, run_id=run_id):
            # Started before plans were stored, in the earliest-start order: unguided from here on
            # rather than decided in an order its record does not have.
            return GuidancePlan((), ())
        original = stored_plan(session, replay_of) if replay_of is not None else None
    plan = original if original is not None else plan_guidance(problem)
    with transaction(sessions) as session:
        lifecycle.record_event(
            session, run_id=run_id, kind=EventKind.GUIDANCE_PLANNED, detail=plan.as_json()
        )
    with sessions() as session:
        # Two processes racing on one run both record one: the first recorded holds.
        return stored_plan(session, run_id) or plan
