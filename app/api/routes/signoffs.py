"""Sign-off of completed runs (supervisor)."""

from __future__ import annotations

from fastapi import APIRouter, Response, status

from app.api.deps import RunIdPath, RunsDep, SupervisorDep
from app.api.idempotency import IdempotencyKey, idempotency_of, mark_replayed
from app.api.responses import BODY, SUPERVISOR, errors
from app.api.schemas.reviews import SignOffRequest
from app.api.schemas.runs import SignedHeadsOut, SignOffOut
from app.audit.signoffs import SignOff
from app.reviews.signoff import sign_off

router = APIRouter(prefix="/runs", tags=["sign-off"])


def signoff_out(signed: SignOff) -> SignOffOut:
    return SignOffOut(
        signer=signed.signer,
        at=signed.at,
        heads=SignedHeadsOut(
            decisions=signed.heads.get("decisions"), events=signed.heads.get("events")
        ),
        statement=signed.statement,
    )


@router.post(
    "/{run_id}/signoff",
    status_code=status.HTTP_201_CREATED,
    response_model=SignOffOut,
    responses=errors(*SUPERVISOR, *BODY, 404, 409),
)
def create_signoff(
    caller: SupervisorDep,
    run_id: RunIdPath,
    body: SignOffRequest,
    runs: RunsDep,
    response: Response,
    idempotency_key: IdempotencyKey,
) -> SignOffOut:
    """For supervisors: sign off a completed run whose record verifies. Records the signer's
    key name, the time, the statement and the heads of the decision and event chains."""
    signed, replayed = sign_off(
        sessions=runs.sessions,
        run_id=run_id,
        signer=caller.name,
        statement=body.statement,
        idempotency=idempotency_of(idempotency_key, body),
        keys=runs.worker.signing_keys,
    )
    mark_replayed(response, replayed)
    return signoff_out(signed)
