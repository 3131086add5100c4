"""Who may execute a run: the strategy a RunWorker is composed with.

- `LocalOwnership` (the embedded SQLite default): this process is the only one on the
  store (an advisory lock proves it), so it owns every run; a run found `running` at
  start-up belonged to a process that died.
- `app.runs.leased.LeaseOwnership` (PostgreSQL scale-out): runs are leased, renewed and
  fenced, so several processes share the database and never execute one run twice.

The worker hands each strategy a `Slots` view of itself (start a run, count free slots,
see the runs it holds), so a strategy decides *which* runs this process executes while the
worker decides *how*.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.runs import lifecycle
from app.runs.lifecycle import EventKind, RunStatus
from app.runs.recorder import Fence, RunStop
from app.runs.store_lock import StoreLock
from app.store import repository as repo
from app.store.db import transaction
from app.store.models import Run


class Slots(Protocol):
    """What a worker offers its ownership strategy."""

    def start(self, run_id: str) -> bool:
        """Execute the run on a free thread; False if it is already held or the worker is
        closing."""

    def free_slots(self) -> int: ...

    def held(self) -> dict[str, RunStop]:
        """The runs this process is executing now, with their stop flags."""


class Ownership(Protocol):
    def attach(self, slots: Slots) -> None:
        """Called once by the worker it is composed into."""

    def submit(self, run_id: str) -> None:
        """A run was created, resumed or queued again here: execute it, or leave it for
        whichever process should."""

    def recover(self) -> list[str]:
        """Start-up: take up what was left; returns the ids of interrupted runs resumed."""

    def is_active(self, run_id: str) -> bool:
        """Whether some process other than this one's threads is executing the run."""

    def owned_run(self, session: Session, run_id: str) -> Run | None:
        """The run, if this process may write its status (locked until commit)."""

    def fence(self, run_id: str, stop: RunStop) -> Fence | None:
        """A check made inside every recorder write, or None."""

    def event_detail(self) -> dict[str, Any]:
        """Added to the started/resumed events (which process ran it)."""

    def finished(self, run_id: str, stop: RunStop) -> None:
        """The worker's thread for the run has ended (whatever the outcome)."""

    def stop_taking(self) -> None:
        """Shutdown begins: claim nothing more."""

    def close(self) -> None:
        """After the worker's runs have stopped: let go of what the strategy holds."""


class LocalOwnership:
    """The single process on an embedded SQLite store."""

    def __init__(self, *, settings: Settings, sessions: sessionmaker[Session]) -> None:
        self._settings = settings
        self._sessions = sessions
        self._release_store = _claim_store(settings.db_url)
        self._slots: Slots | None = None

    def attach(self, slots: Slots) -> None:
        self._slots = slots

    @property
    def slots(self) -> Slots:
        if self._slots is None:
            raise RuntimeError("LocalOwnership is used before a worker attached it")
        return self._slots

    def submit(self, run_id: str) -> None:
        self.slots.start(run_id)

    def recover(self) -> list[str]:
        """Runs found `running` were orphaned by a dead process: mark them interrupted, then
        start the queued ones and (with auto-resume) the interrupted ones."""
        with transaction(self._sessions) as session:
            for run in repo.runs_with_status(session=session, statuses=[RunStatus.RUNNING]):
                lifecycle.move(
                    session,
                    run,
                    RunStatus.INTERRUPTED,
                    event=EventKind.INTERRUPTED,
                    detail={"reason": "found running at start-up; the process that ran it stopped"},
                )
            queued = [
                r.id for r in repo.runs_with_status(session=session, statuses=[RunStatus.QUEUED])
            ]
            interrupted = [
                r.id
                for r in repo.runs_with_status(session=session, statuses=[RunStatus.INTERRUPTED])
            ]
        for run_id in queued:
            self.submit(run_id)
        if not self._settings.auto_resume:
            return []
        for run_id in interrupted:
            self.submit(run_id)
        return interrupted

    def is_active(self, run_id: str) -> bool:
        return False  # no other process runs anything on this store

    def owned_run(self, session: Session, run_id: str) -> Run | None:
        # Locked as the protocol says (on SQLite: the write lock first), so the status read
        # is the one this transaction's move replaces: a cancel committed between a plain
        # read and the worker's write was overwritten (a cancelled run set running again).
        return repo.get_run(session=session, run_id=run_id, for_update=True)

    def fence(self, run_id: str, stop: RunStop) -> Fence | None:
        return None

    def event_detail(self) -> dict[str, Any]:
        return {}

    def finished(self, run_id: str, stop: RunStop) -> None:
        pass

    def stop_taking(self) -> None:
        pass

    def close(self) -> None:
        self._release_store()


def _claim_store(database_url: str) -> Callable[[], None]:
    """Make this the only process on the embedded store (StoreInUseError otherwise);
    returns how to let go. An in-memory or non-SQLite database needs no lock."""
    url = make_url(database_url)
    database = url.database
    if url.get_backend_name() != "sqlite" or not database or database == ":memory:":
        return lambda: None
    lock = StoreLock(Path(database))
    lock.acquire()
    return lock.release
