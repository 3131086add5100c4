"""Export a run's whole audit record as self-describing JSON lines: the format
scripts/check_trace.py verifies offline and archives are written in."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import datetime
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from app.audit.heads import geneses as chain_geneses
from app.audit.record_pages import (
    annotation_pages,
    chain_passes,
    columns,
    decision_pages,
    event_pages,
    run_or_missing,
)
from app.reasoners.attribution import Attribution, attempt_attribution, decision_attribution
from app.store import chain
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.models import Attempt, Decision, Run, RunAnnotation, RunEvent, as_utc


def _when(value: datetime | None) -> str | None:
    return as_utc(value).isoformat() if value is not None else None


def _run_line(run: Run) -> dict[str, Any]:
    return {
        "type": "run",
        "format": run.chain_scheme or chain.SCHEME,
        "chain_scheme": run.chain_scheme or chain.SCHEME,
        "id": run.id,
        "status": run.status,
        "reasoner": run.reasoner,
        "mode": run.mode,
        "max_deviation": run.max_deviation,
        "n_tasks": run.n_tasks,
        "n_robots": run.n_robots,
        "resumes": run.resumes,
        "error": run.error,
        "created_at": _when(run.created_at),
        "finished_at": _when(run.finished_at),
        "request": run.request,
        "revision_of": run.revision_of,
        "revision": run.revision,
        "genesis": chain_geneses(run),
    }


def _event_line(e: RunEvent) -> dict[str, Any]:
    return {
        "type": "event",
        **columns(e, chain.EVENT_FIELDS),
        "at": _when(e.created_at),
        "chain_hash": e.chain_hash,
    }


def _annotation_line(a: RunAnnotation) -> dict[str, Any]:
    return {
        "type": "annotation",
        **columns(a, chain.ANNOTATION_FIELDS),
        "at": _when(a.created_at),
        "chain_hash": a.chain_hash,
    }


def _attempt_line(a: Attempt, run_reasoner: str) -> tuple[dict[str, Any], Attribution]:
    who = attempt_attribution(a.reply_extra, a.reply_model, run_reasoner)
    line = {
        **columns(a, chain.ATTEMPT_FIELDS),
        "at": _when(a.created_at),
        "reasoner": who.reasoner,
        "why": who.why,
    }
    return line, who


def _decision_line(d: Decision, attempts: list[Attempt], run_reasoner: str) -> dict[str, Any]:
    # Columns under their stored names, so the export alone suffices to recompute the chain;
    # `reasoner` and `why` (derived, outside the chain) say who wrote each reply.
    lines = [_attempt_line(a, run_reasoner) for a in attempts]
    accepted = next((who for line, who in reversed(lines) if line["accepted"]), None)
    decided = decision_attribution(bool(d.fallback), accepted)
    return {
        "type": "decision",
        **chain.decision_columns(d),
        "at": _when(d.created_at),
        "chain_hash": d.chain_hash,
        "reasoner": decided.reasoner,
        "why": decided.why,
        "attempt_records": [line for line, _ in lines],
    }


def trace_record(
    *,
    sessions: sessionmaker[Session],
    run_id: str,
) -> Iterator[list[dict[str, Any]]]:
    """The whole audit record as pages of self-describing lines: the run, its events, its
    decisions (each with its attempts, prompts and replies), its annotations (what was
    recorded after it finished: sign-offs, execution reports), then an end line with counts
    so a reader can tell a complete record from a cut-off download.

    Raises RunNotFoundError here, before the first page is asked for."""
    with sessions() as session:
        header = _run_line(run_or_missing(session, run_id))
        header["signatures"] = [
            {
                "reason": s.reason,
                "key_id": s.key_id,
                "payload": s.payload,
                "signature": s.signature,
                "at": _when(s.created_at),
            }
            for s in repo.signatures(session=session, run_id=run_id)
        ]
    return _record_pages(sessions, run_id, header)


def _record_pages(
    sessions: sessionmaker[Session], run_id: str, header: dict[str, Any]
) -> Iterator[list[dict[str, Any]]]:
    yield [header]
    n_events = n_decisions = n_attempts = 0
    for events in event_pages(sessions, run_id):
        n_events += len(events)
        yield [_event_line(e) for e in events]
    # In chain order, so a checker links the lines as they come (a revision: pins first).
    with sessions() as session:
        sequenced = decision_repo.sequenced_order(session=session, run_id=run_id) is not None
    for pinned, by_seq in chain_passes(header["revision_of"], sequenced):
        for decisions in decision_pages(sessions, run_id, pinned, by_seq):
            n_decisions += len(decisions)
            n_attempts += sum(len(a) for _, a in decisions)
            yield [_decision_line(d, a, header["reasoner"]) for d, a in decisions]
    n_annotations = 0
    for annotation_page in annotation_pages(sessions, run_id):
        n_annotations += len(annotation_page)
        yield [_annotation_line(a) for a in annotation_page]
    yield [
        {
            "type": "end",
            "events": n_events,
            "decisions": n_decisions,
            "attempts": n_attempts,
            "annotations": n_annotations,
        }
    ]
