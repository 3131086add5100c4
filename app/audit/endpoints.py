"""GET /audit/public-key: what verifies signed chain heads, with no secret."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated

from fastapi import APIRouter, Depends, Request
from pydantic import BaseModel, Field

from app.audit.signing import ALGORITHM, SigningKeys, public_pem
from app.http.deps import ClientDep
from app.http.errors import ApiError
from app.http.responses import CLIENT, errors

router = APIRouter(prefix="/audit", tags=["audit"])

# The keys the run worker signs with. Handed in by app.api.routers as
# `app.state.signing_keys` (the worker lives in app.runs, a layer above this package).
SigningKeysSource = Callable[[], SigningKeys]


def get_signing_keys(request: Request) -> SigningKeys:
    source: SigningKeysSource = request.app.state.signing_keys
    return source()


SigningKeysDep = Annotated[SigningKeys, Depends(get_signing_keys)]


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
def public_key(caller: ClientDep, keys: SigningKeysDep) -> PublicKeysOut:
    """The public keys that verify signed chain heads (the current one and retired ones)."""
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
