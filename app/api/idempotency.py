"""The Idempotency-Key header of POST /runs, as the route reads and documents it."""

from __future__ import annotations

import re
from typing import Annotated, Any

from fastapi import Depends, Header, Request
from pydantic import BaseModel

from app.api.errors import ApiError
from app.api.openapi import header_schema
from app.runs.idempotency import HEADER, MAX_KEY_LENGTH, Idempotency, request_digest

REPLAYED_HEADER = "Idempotent-Replayed"
# Visible ASCII, spaces only inside: what survives every proxy unchanged.
KEY_PATTERN = r"^[!-~]([ -~]*[!-~])?$"
_KEY = re.compile(KEY_PATTERN)

_KeyHeader = Annotated[
    str | None,
    Header(
        alias=HEADER,
        min_length=1,
        max_length=MAX_KEY_LENGTH,
        json_schema_extra=header_schema(minLength=1, maxLength=MAX_KEY_LENGTH, pattern=KEY_PATTERN),
        description="Makes retries safe: a unique value per run you mean to start (e.g. a UUID). "
        "Resending the same key with the same body returns the run the first request created "
        f"(202, same body and Location, `{REPLAYED_HEADER}: true`) instead of starting another; "
        "the same key with a different body is a 409. Keys are global, not per API key.",
    ),
]


def _one_key(request: Request, key: _KeyHeader = None) -> str | None:
    # The header parameter alone reads only the first of several: a retry repeating the
    # other one (or a proxy joining them into "a, b") would then start another run.
    sent = len(request.headers.getlist(HEADER))
    if sent > 1:
        raise ApiError(
            422,
            ["header", HEADER],
            f"{sent} {HEADER} headers were sent; send exactly one, with one key",
            "duplicate_header",
        )
    if key is not None and _KEY.match(key) is None:
        raise ApiError(
            422,
            ["header", HEADER],
            f"{HEADER} must be visible ASCII characters (spaces only between them), e.g. a UUID",
            "invalid_header",
        )
    return key


IdempotencyKey = Annotated[str | None, Depends(_one_key)]

CREATED_HEADERS: dict[str, Any] = {
    "Location": {"description": "The run: /runs/{id}", "schema": {"type": "string"}},
    REPLAYED_HEADER: {
        "description": f"`true` when an earlier request with the same {HEADER} and body "
        "created the run",
        "schema": {"type": "string", "enum": ["true"]},
    },
}


def idempotency_of(key: str | None, body: BaseModel) -> Idempotency | None:
    # Only the fields the client sent: an explicit `"max_deviation": null` (no cap) and an
    # omitted one (the mode's cap) are different requests.
    if key is None:
        return None
    return Idempotency(
        key=key, digest=request_digest(body.model_dump(mode="json", exclude_unset=True))
    )
