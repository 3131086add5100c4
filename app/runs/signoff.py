"""Sign-off of a completed run: a named supervisor states that they have read its record,
and the heads of its decision and event chains are recorded with the statement.

A sign-off is an annotation (app.domain.annotations): it never changes the run's decisions
or events, so `trace/verify` can later tell whether those chains still end at the heads
that were signed (`signoffs_ok`).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from app.domain.annotations import AnnotationKind
from app.domain.errors import DomainError, refuse_nul
from app.runs import audit, lifecycle
from app.runs.errors import RunStateConflictError
from app.runs.idempotency import Idempotency, IdempotencyKeyReusedError
from app.runs.lifecycle import RunStatus
from app.runs.signing import SigningKeys, sign_run
from app.runs.tombstones import missing_run
from app.store import repository as repo
from app.store.db import transaction
from app.store.models import Decision, RunAnnotation, RunEvent, as_utc, utcnow


@dataclass(frozen=True)
class SignOff:
    signer: str
    at: datetime
    heads: dict[str, str | None]
    statement: str

    @classmethod
    def of(cls, row: RunAnnotation) -> SignOff:
        detail = row.detail or {}
        return cls(
            signer=str(detail["signer"]),
            at=as_utc(datetime.fromisoformat(detail["at"])),
            heads=dict(detail["heads"]),
            statement=str(detail["statement"]),
        )


def _heads(session: Session, run_id: str) -> dict[str, str | None]:
    decision = session.scalar(
        select(Decision.chain_hash)
        .where(Decision.run_id == run_id)
        .order_by(Decision.task_index.desc())
        .limit(1)
    )
    event = session.scalar(
        select(RunEvent.chain_hash)
        .where(RunEvent.run_id == run_id)
        .order_by(RunEvent.seq.desc())
        .limit(1)
    )
    return {"decisions": decision, "events": event}


def sign_off(
    *,
    sessions: sessionmaker[Session],
    run_id: str,
    signer: str,
    statement: str,
    idempotency: Idempotency | None = None,
    keys: SigningKeys | None = None,
) -> tuple[SignOff, bool]:
    """(the sign-off, whether an earlier request with the same Idempotency-Key made it).

    RunStateConflictError unless the run completed and its record verifies: a signature
    over a record that is already broken would vouch for the break."""
    if not statement.strip():
        # Like an override's reason: whitespace alone states nothing.
        raise DomainError(
            "statement", "a sign-off needs a statement, not only whitespace", code="missing"
        )
    refuse_nul("statement", statement)
    if idempotency is not None:
        earlier = _for_key(sessions, idempotency, run_id)
        if earlier is not None:
            return earlier, True
    with sessions() as session:
        run = repo.get_run(session=session, run_id=run_id)
        if run is None:
            raise missing_run(session, run_id)
        if run.status != RunStatus.COMPLETED:
            raise RunStateConflictError(
                run_id, run.status, "sign off", "Only a completed run can be signed off."
            )
    report = audit.verify_trace(sessions=sessions, run_id=run_id)
    if report.decisions.first_break is not None or report.events.first_break is not None:
        raise RunStateConflictError(
            run_id,
            "completed",
            "sign off",
            "Its record does not verify (see GET /runs/{id}/trace/verify); "
            "a sign-off would vouch for the break.",
        )
    try:
        with transaction(sessions) as session:
            # Locked: two sign-offs at once take their turns on the annotation chain.
            repo.get_run(session=session, run_id=run_id, for_update=True)
            at = utcnow()
            detail: dict[str, Any] = {
                "signer": signer,
                "at": at.isoformat(),
                "heads": _heads(session, run_id),
                "statement": statement,
            }
            row = lifecycle.record_annotation(
                session,
                run_id=run_id,
                kind=AnnotationKind.SIGNOFF,
                detail=detail,
                idempotency_key=idempotency.key if idempotency else None,
                request_digest=idempotency.digest if idempotency else None,
            )
            signed = SignOff.of(row)
    except IntegrityError:
        # The unique key decides between two requests with one Idempotency-Key at once.
        if idempotency is None:
            raise
        earlier = _for_key(sessions, idempotency, run_id)
        if earlier is None:
            raise
        return earlier, True
    if keys is not None:
        # With a server key the heads are signed at each sign-off too (app.runs.signing).
        sign_run(sessions=sessions, keys=keys, run_id=run_id, reason="signoff")
    return signed, False


def _for_key(
    sessions: sessionmaker[Session], idempotency: Idempotency, run_id: str
) -> SignOff | None:
    with sessions() as session:
        row = repo.annotation_for_key(session=session, idempotency_key=idempotency.key)
    if row is None:
        return None
    if row.request_digest != idempotency.digest or row.run_id != run_id:
        raise IdempotencyKeyReusedError(row.run_id)
    return SignOff.of(row)


def signoffs(*, session: Session, run_id: str) -> list[SignOff]:
    return [
        SignOff.of(row)
        for row in repo.annotations_page(
            session=session, run_id=run_id, kind=AnnotationKind.SIGNOFF.value
        )
    ]
