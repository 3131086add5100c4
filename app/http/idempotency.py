"""The Idempotency-Key header, as the routes read and document it, and the request it keys."""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Annotated, Any

from fastapi import Depends, Header, Request, Response
from pydantic import BaseModel

from app.http.errors import ApiError
from app.http.responses import header_schema
from app.store.idempotency import HEADER, MAX_KEY_LENGTH, Idempotency, request_digest

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


def refuse_repeated_key(request: Request) -> None:
    # The header parameter alone reads only the first of several: a retry repeating the
    # other one (or a proxy joining them into "a, b") would then act twice.
    sent = len(request.headers.getlist(HEADER))
    if sent > 1:
        raise ApiError(
            422,
            ["header", HEADER],
            f"{sent} {HEADER} headers were sent; send exactly one, with one key",
            "duplicate_header",
        )


def checked_key(request: Request, key: str | None) -> str | None:
    """The one Idempotency-Key sent, if any, checked as every route documents it."""
    refuse_repeated_key(request)
    if key is not None and _KEY.match(key) is None:
        raise ApiError(
            422,
            ["header", HEADER],
            f"{HEADER} must be visible ASCII characters (spaces only between them), e.g. a UUID",
            "invalid_header",
        )
    return key


def _one_key(request: Request, key: _KeyHeader = None) -> str | None:
    return checked_key(request, key)


IdempotencyKey = Annotated[str | None, Depends(_one_key)]

CREATED_HEADERS: dict[str, Any] = {
    "Location": {"description": "The run: /runs/{id}", "schema": {"type": "string"}},
    REPLAYED_HEADER: {
        "description": f"`true` when an earlier request with the same {HEADER} and body "
        "created the run",
        "schema": {"type": "string", "enum": ["true"]},
    },
}


def keyed(key: str | None, request: Mapping[str, Any]) -> Idempotency | None:
    """The key with the digest of what the route counts as its request; None without one."""
    return None if key is None else Idempotency(key=key, digest=request_digest(request))


def idempotency_of(key: str | None, body: BaseModel) -> Idempotency | None:
    # Only the fields the client sent: an explicit `"max_deviation": null` (no cap) and an
    # omitted one (the mode's cap) are different requests. No key, no digest: dumping a
    # large body (a 1,000-task timed instance) for nothing costs the request time.
    if key is None:
        return None
    return keyed(key, body.model_dump(mode="json", exclude_unset=True))


def mark_replayed(response: Response, replayed: bool) -> None:
    """Tells the client that an earlier request with the same key made this answer."""
    if replayed:
        response.headers[REPLAYED_HEADER] = "true"
