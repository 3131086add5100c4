"""Sign-off of a completed run: a named supervisor states that they have read its record,
and the heads of its decision and event chains are recorded with the statement.

A sign-off is an annotation (app.domain.annotations): it never changes the run's decisions
or events, so `trace/verify` can later tell whether those chains still end at the heads
that were signed (`signoffs_ok`).
"""

from __future__ import annotations

from typing import Any

from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from app.audit.heads import chain_heads
from app.audit.signing import SigningKeys, sign_in
from app.audit.signoffs import SignOff
from app.audit.verify import verify_trace
from app.domain.annotations import AnnotationKind
from app.domain.errors import (
    DomainError,
    IdempotencyKeyReusedError,
    RunStateConflictError,
    refuse_nul,
)
from app.runs import lifecycle
from app.runs.lifecycle import RunStatus
from app.store import repository as repo
from app.store.db import transaction
from app.store.idempotency import Idempotency
from app.store.models import utcnow
from app.store.tombstones import missing_run


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
    report = verify_trace(sessions=sessions, run_id=run_id)
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
            locked = repo.get_run(session=session, run_id=run_id, for_update=True)
            at = utcnow()
            detail: dict[str, Any] = {
                "signer": signer,
                "at": at.isoformat(),
                "heads": chain_heads(session, run_id).as_dict(),
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
            if keys is not None and locked is not None:
                # With a server key the heads are signed at each sign-off too, in its
                # transaction (app.audit.signing.sign_in).
                sign_in(session, keys, locked, "signoff")
            signed = SignOff.of(row)
    except IntegrityError:
        # The unique key decides between two requests with one Idempotency-Key at once.
        if idempotency is None:
            raise
        earlier = _for_key(sessions, idempotency, run_id)
        if earlier is None:
            raise
        return earlier, True
    return signed, False


def _for_key(
    sessions: sessionmaker[Session], idempotency: Idempotency, run_id: str
) -> SignOff | None:
    with sessions() as session:
        row = repo.annotation_for_key(session=session, idempotency_key=idempotency.key)
    if row is None:
        return None
    if row.request_digest != idempotency.digest or row.run_id != run_id:
        raise IdempotencyKeyReusedError.for_run(row.run_id)
    return SignOff.of(row)
