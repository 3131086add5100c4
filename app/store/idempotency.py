"""Idempotency keys on run creation: a retried POST /runs gets the run its first try created.

Site software retries over bad networks; without a key, a retry whose first try did reach
the server would start a second, identical run. Keys are global, not per API key.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from app.domain.errors import IDEMPOTENCY_HEADER, IdempotencyKeyReusedError
from app.store.models import Run

HEADER = IDEMPOTENCY_HEADER
MAX_KEY_LENGTH = 255  # the width of runs.idempotency_key


@dataclass(frozen=True)
class Idempotency:
    key: str
    digest: str  # of the request the key came with; see request_digest


def request_digest(body: Mapping[str, Any]) -> str:
    """SHA-256 of the canonical JSON of a validated request body, so that key order and
    whitespace do not make a retry look like a different request."""
    canonical = json.dumps(
        body, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False
    )
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()


def run_for_key(*, sessions: sessionmaker[Session], idempotency: Idempotency) -> Run | None:
    """The run created under this key, if any; IdempotencyKeyReusedError (409) if it was
    created by a request with another body."""
    with sessions() as session:
        run = session.scalar(select(Run).where(Run.idempotency_key == idempotency.key))
    if run is not None and run.request_digest != idempotency.digest:
        raise IdempotencyKeyReusedError.for_run(run.id)
    return run
