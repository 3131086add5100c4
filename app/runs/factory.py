"""The run worker for the configured database: leases on PostgreSQL, one process on SQLite."""

from __future__ import annotations

from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.runs.worker import RunWorker


def uses_leases(database_url: str) -> bool:
    """SQLite is the single-process embedded store (its checkpointer is a local file), so
    runs are recovered at start-up; PostgreSQL may be shared by several processes."""
    return make_url(database_url).get_backend_name() == "postgresql"


def make_worker(*, settings: Settings, sessions: sessionmaker[Session]) -> RunWorker:
    if uses_leases(settings.db_url):
        from app.runs.leased import LeasedRunWorker

        return LeasedRunWorker(settings=settings, sessions=sessions)
    return RunWorker(settings=settings, sessions=sessions)
