"""GET /audit/public-key: what verifies signed chain heads, with no secret."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel, Field

from app.audit.signing import ALGORITHM, public_pem
from app.http.deps import ClientDep
from app.http.errors import ApiError
from app.http.responses import CLIENT, errors
from app.runs.deps import RunsDep

router = APIRouter(prefix="/audit", tags=["audit"])


class PublicKeyOut(BaseModel):
    key_id: str
    public_key_pem: str


class PublicKeysOut(BaseModel):
    algorithm: str = Field(description="Ed25519")
    current: PublicKeyOut = Field(description="The key new signatures are made with")
    retired: list[PublicKeyOut] = Field(
        description="Keys of earlier signatures, kept so that old runs still verify"
    )


@router.get("/public-key", response_model=PublicKeysOut, responses=errors(*CLIENT, 404))
def public_key(caller: ClientDep, runs: RunsDep) -> PublicKeysOut:
    """The public keys that verify signed chain heads (the current one and retired ones)."""
    keys = runs.worker.signing_keys
    current = keys.current_id
    if current is None:
        raise ApiError(
            404,
            ["path"],
            "this server has no signing key (LTAA_SIGNING_KEY_FILE): heads are not signed",
            "no_signing_key",
        )
    return PublicKeysOut(
        algorithm=ALGORITHM,
        current=PublicKeyOut(key_id=current, public_key_pem=public_pem(keys.public[current])),
        retired=[
            PublicKeyOut(key_id=k, public_key_pem=public_pem(v))
            for k, v in sorted(keys.public.items())
            if k != current
        ],
    )
