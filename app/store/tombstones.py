"""What a lookup of a run id with no row answers: 410 Gone naming the archive, or 404."""

from __future__ import annotations

from sqlalchemy.orm import Session, sessionmaker

from app.domain.errors import DomainError, RunArchivedError, RunNotFoundError
from app.store.models import ArchivedRun


def missing_run(session: Session, run_id: str) -> DomainError:
    gone = session.get(ArchivedRun, run_id)
    if gone is not None:
        return RunArchivedError(run_id, gone.archive_file)
    return RunNotFoundError(run_id)


def archive_file_of(*, sessions: sessionmaker[Session], run_id: str) -> str | None:
    """The archive file of an archived run, or None (never archived, or no such run)."""
    with sessions() as session:
        gone = session.get(ArchivedRun, run_id)
        return gone.archive_file if gone is not None else None
