"""Run leases: which process executes a run, and until when (PostgreSQL scale-out).

`lease_owner` is the fencing token: every write a run makes is conditional on it, so a
process that lost a run (its lease expired and another process took the run) cannot
write for it again. Times come from the database clock (`now()`), so processes on hosts
with skewed clocks agree on when a lease has expired. Claims lock rows with
`FOR UPDATE SKIP LOCKED`: concurrent pollers each get different runs and never wait.
"""

from __future__ import annotations

import os
import socket
import uuid
from collections.abc import Sequence
from datetime import timedelta
from typing import Any

from sqlalchemy import ColumnElement, and_, func, or_, select, update
from sqlalchemy.orm import Session

from app.domain.lifecycle import CLAIMABLE as CLAIMABLE_STATUSES
from app.domain.lifecycle import RunStatus
from app.store.models import Run

CLAIMABLE = tuple(sorted(CLAIMABLE_STATUSES))


def lease_owner_id(name: str | None) -> str:
    """A lease holder's name, unique per process start: a restarted process must not inherit
    its old leases, or it would skip the integrity check for runs it never ran (and the
    fleet bridge's lease, app.fleet.lease, names its holders the same way)."""
    return f"{name or socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


def _expires(lease_s: float) -> Any:
    return func.now() + timedelta(seconds=lease_s)


def unleased() -> ColumnElement[bool]:
    """Nobody holds the run's lease (never leased, released, or expired)."""
    return or_(Run.lease_expires_at.is_(None), Run.lease_expires_at < func.now())


def _no_sync(stmt: Any) -> Any:
    # The ORM cannot evaluate now() in Python; callers re-read rows they need.
    return stmt.execution_options(synchronize_session=False)


def expired_running(*, session: Session) -> list[tuple[Run, str | None]]:
    """Runs `running` under an expired lease: their process died or stalled. Each is locked
    and unleased, and returned with its previous owner; the caller moves it to interrupted
    (app.runs.lifecycle) in the same transaction."""
    rows = session.scalars(
        select(Run)
        .where(Run.status == RunStatus.RUNNING, unleased())
        .order_by(Run.created_at)
        .with_for_update(skip_locked=True)
    ).all()
    reaped = []
    for run in rows:
        reaped.append((run, run.lease_owner))
        run.lease_owner = None
        run.lease_expires_at = None
    return reaped


def claim_runs(
    *, session: Session, owner: str, lease_s: float, limit: int, statuses: Sequence[str]
) -> list[tuple[str, str]]:
    """Lease up to `limit` unleased runs in one of `statuses`, oldest first: (id, status)."""
    if limit <= 0 or not statuses:
        return []
    rows = session.execute(
        select(Run.id, Run.status)
        .where(Run.status.in_(statuses), unleased())
        .order_by(Run.created_at, Run.id)
        .limit(limit)
        .with_for_update(skip_locked=True)
    ).all()
    ids = [r.id for r in rows]
    if ids:
        session.execute(
            _no_sync(
                update(Run)
                .where(Run.id.in_(ids))
                .values(lease_owner=owner, lease_expires_at=_expires(lease_s))
            )
        )
    return [(r.id, r.status) for r in rows]


def claim_run(*, session: Session, run_id: str, owner: str, lease_s: float) -> bool:
    """Lease one run if it is claimable and nobody holds it (one conditional UPDATE)."""
    stmt = (
        update(Run)
        .where(Run.id == run_id, Run.status.in_(CLAIMABLE), unleased())
        .values(lease_owner=owner, lease_expires_at=_expires(lease_s))
        .returning(Run.id)
    )
    return session.execute(_no_sync(stmt)).first() is not None


def renew(
    *, session: Session, owner: str, run_ids: Sequence[str], lease_s: float
) -> dict[str, bool]:
    """Extend the leases `owner` still holds: {run id: cancel requested}. A run missing
    from the answer was taken from this owner."""
    if not run_ids:
        return {}
    stmt = (
        update(Run)
        .where(Run.id.in_(run_ids), Run.lease_owner == owner)
        .values(lease_expires_at=_expires(lease_s))
        .returning(Run.id, Run.cancel_requested)
    )
    return {r.id: bool(r.cancel_requested) for r in session.execute(_no_sync(stmt))}


def release(*, session: Session, run_id: str, owner: str) -> None:
    session.execute(
        _no_sync(
            update(Run)
            .where(Run.id == run_id, Run.lease_owner == owner)
            .values(lease_owner=None, lease_expires_at=None)
        )
    )


def is_leased(*, session: Session, run_id: str) -> bool:
    return (
        session.scalar(
            select(Run.id).where(
                Run.id == run_id,
                and_(Run.lease_owner.is_not(None), Run.lease_expires_at >= func.now()),
            )
        )
        is not None
    )
