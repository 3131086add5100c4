"""Sign-off of completed runs (supervisor)."""

from __future__ import annotations

from fastapi import APIRouter, Response, status

from app.http.deps import SupervisorDep
from app.http.idempotency import IdempotencyKey, idempotency_of, mark_replayed
from app.http.responses import BODY, SUPERVISOR, errors
from app.reviews.schemas import SignOffRequest
from app.reviews.signoff import sign_off
from app.runs.deps import RunIdPath, RunsDep
from app.runs.schemas import SignOffOut, signoff_out

router = APIRouter(prefix="/runs", tags=["sign-off"])


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
