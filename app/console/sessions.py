"""Console sessions: a random token in an HttpOnly cookie, a row per session in the app
database (the token's digest, the key's fingerprint, a CSRF token, the expiry).

Every request re-checks the fingerprint against the keys configured now, so removing a key
from LTAA_API_KEYS (and restarting) ends its sessions without touching the table.
"""

from __future__ import annotations

import hashlib
import secrets
from dataclasses import dataclass
from datetime import timedelta

from sqlalchemy import delete
from sqlalchemy.orm import Session, sessionmaker

from app.http.auth import ANONYMOUS, KeyRing, Role
from app.store.db import transaction
from app.store.models import ConsoleSession, as_utc, utcnow

COOKIE = "ltaa_console"
LOGIN_CSRF_COOKIE = "ltaa_console_login"


def _digest(token: str) -> str:
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def new_token() -> str:
    return secrets.token_urlsafe(32)


@dataclass(frozen=True)
class SignedIn:
    """Who is using the console: a supervisor key's session, or anyone while access is off."""

    token: str
    csrf_token: str
    anonymous: bool
    name: str = ANONYMOUS  # the key's non-secret name: what reviews and sign-offs record


def open_session(
    *,
    sessions: sessionmaker[Session],
    fingerprint: str | None,
    lifetime_s: float,
    name: str = ANONYMOUS,
) -> SignedIn:
    token = new_token()
    csrf = secrets.token_urlsafe(32)
    now = utcnow()
    with transaction(sessions) as session:
        # Expired rows are dropped here, at sign-in, rather than by a background sweep.
        session.execute(delete(ConsoleSession).where(ConsoleSession.expires_at < now))
        session.add(
            ConsoleSession(
                token_digest=_digest(token),
                key_fingerprint=fingerprint,
                csrf_token=csrf,
                created_at=now,
                expires_at=now + timedelta(seconds=lifetime_s),
            )
        )
    return SignedIn(token=token, csrf_token=csrf, anonymous=fingerprint is None, name=name)


def current(
    *, sessions: sessionmaker[Session], keyring: KeyRing, token: str | None
) -> SignedIn | None:
    """The live session a cookie names, or None: unknown, expired, opened with a key that is
    no longer a configured supervisor key, or opened keyless while keys are configured."""
    if not token:
        return None
    with sessions() as session:
        row = session.get(ConsoleSession, _digest(token))
        if row is None or as_utc(row.expires_at) <= utcnow():
            return None
        fingerprint, csrf = row.key_fingerprint, row.csrf_token
    if fingerprint is None:
        return SignedIn(token=token, csrf_token=csrf, anonymous=True) if keyring.open else None
    found = keyring.identify_fingerprint(fingerprint)
    if found is None or found[0] is not Role.SUPERVISOR:
        return None
    return SignedIn(token=token, csrf_token=csrf, anonymous=False, name=found[1])


def close_session(*, sessions: sessionmaker[Session], token: str) -> None:
    with transaction(sessions) as session:
        session.execute(delete(ConsoleSession).where(ConsoleSession.token_digest == _digest(token)))
