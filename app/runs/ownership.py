"""Who may execute a run: the strategy a RunWorker is composed with.

- `LocalOwnership` (the embedded SQLite default): this process is the only one on the
  store (an advisory lock proves it), so it owns every run; a run found `running` at
  start-up belonged to a process that died.
- `LeaseOwnership` (PostgreSQL scale-out): runs are leased, renewed and fenced, so
  several processes share the database and never execute one run twice.

The worker hands each strategy a `Slots` view of itself (start a run, count free slots,
see the runs it holds), so a strategy decides *which* runs this process executes while the
worker decides *how*.

Leases, in detail (several API processes sharing runs on one PostgreSQL database):

- Claim: a process with a free slot leases runs that are `queued` (or `interrupted`, with
  auto-resume) and unleased, with `SELECT ... FOR UPDATE SKIP LOCKED` (a background poll
  every `claim_poll_s`; `POST /runs` and resume also claim at once). Only the lease
  holder executes a run.
- Renew: a heartbeat thread extends every held lease each `lease_s / 3`, and every
  recorder write renews its run's lease in the write's own transaction. Both are
  conditional on still owning the run: a process that lost a lease (it stalled past
  expiry and another process took the run) stops that run at once, writing nothing.
- Take over: a run `running` under an expired lease belonged to a process that died. Any
  poller marks it `interrupted` (an event naming the lost owner) and it is claimed like
  any interrupted run; the resume goes through the usual integrity check and `resumed`
  event, from the Postgres checkpointer shared by all processes.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.runs import lifecycle
from app.runs.lifecycle import EventKind, RunStatus
from app.runs.recorder import Fence, RunStop, lease_fence
from app.store import leases
from app.store import repository as repo
from app.store.db import transaction
from app.store.leases import lease_owner_id
from app.store.lock import StoreLock
from app.store.models import Run

log = logging.getLogger("ltaa.runs")


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

    def __init__(
        self, *, settings: Settings, sessions: sessionmaker[Session], serving: str | None = None
    ) -> None:
        self._settings = settings
        self._sessions = sessions
        self._release_store = _claim_store(settings.db_url, serving)
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


def _claim_store(database_url: str, serving: str | None = None) -> Callable[[], None]:
    """Make this the only process on the embedded store (StoreInUseError otherwise),
    recording where it serves; returns how to let go. An in-memory or non-SQLite database
    needs no lock."""
    url = make_url(database_url)
    database = url.database
    if url.get_backend_name() != "sqlite" or not database or database == ":memory:":
        return lambda: None
    lock = StoreLock(Path(database))
    lock.acquire(serving)
    return lock.release


# -- PostgreSQL scale-out: leases ------------------------------------------------------------


class Periodic:
    """Calls `fn` every `interval_s` on a daemon thread until stopped; errors are logged,
    never fatal (a database blip must not end the heartbeat)."""

    def __init__(self, name: str, interval_s: float, fn: Callable[[], object]) -> None:
        self._interval_s = interval_s
        self._fn = fn
        self._stopped = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stopped.set()
        if self._thread.is_alive():
            self._thread.join()

    def _loop(self) -> None:
        while not self._stopped.wait(self._interval_s):
            try:
                self._fn()
            except Exception:
                log.exception("%s failed; retrying in %.1f s", self._thread.name, self._interval_s)


class LeaseOwnership:
    """The Ownership strategy of a process sharing runs with others on PostgreSQL."""

    def __init__(self, *, settings: Settings, sessions: sessionmaker[Session]) -> None:
        self.owner = lease_owner_id(settings.worker_name)
        self._settings = settings
        self._sessions = sessions
        self._lease_s = settings.lease_s
        self._slots: Slots | None = None
        # Serialises this process's claims so that free slots are counted once.
        self._claim_lock = threading.Lock()
        self._heartbeat = Periodic("ltaa-lease-heartbeat", settings.lease_s / 3, self._renew)
        self._poller = Periodic("ltaa-run-claims", settings.claim_poll_s, self._poll)

    def attach(self, slots: Slots) -> None:
        self._slots = slots
        # Started now, not in recover(): `ltaa run` claims runs without ever polling.
        self._heartbeat.start()

    @property
    def slots(self) -> Slots:
        if self._slots is None:
            raise RuntimeError("LeaseOwnership is used before a worker attached it")
        return self._slots

    # -- the Ownership protocol --------------------------------------------------------

    def recover(self) -> list[str]:
        """Start-up: take what is waiting now, then keep polling. Runs that other live
        processes hold are left alone; their leases say so."""
        resumed = self._poll()
        self._poller.start()
        return resumed

    def stop_taking(self) -> None:
        self._poller.stop()

    def close(self) -> None:
        # Draining runs have marked themselves interrupted and released their leases, so a
        # peer resumes them at its next poll instead of after lease expiry.
        self._heartbeat.stop()

    def submit(self, run_id: str) -> None:
        with self._claim_lock:
            if self.slots.free_slots() > 0:
                with transaction(self._sessions) as session:
                    claimed = leases.claim_run(
                        session=session, run_id=run_id, owner=self.owner, lease_s=self._lease_s
                    )
                if claimed:
                    self._start_claimed(run_id)
                    return
        # No room here, or another process has it: queued runs go to whichever process
        # has a free slot first, so an explicitly resumed run is queued too.
        with transaction(self._sessions) as session:
            lifecycle.move_where(
                session,
                run_id=run_id,
                current=RunStatus.INTERRUPTED,
                to=RunStatus.QUEUED,
                where=(leases.unleased(),),
            )

    def is_active(self, run_id: str) -> bool:
        with self._sessions() as session:
            return leases.is_leased(session=session, run_id=run_id)

    def owned_run(self, session: Session, run_id: str) -> Run | None:
        # The row lock makes "still mine" hold until this transaction commits.
        run = repo.get_run(session=session, run_id=run_id, for_update=True)
        return run if run is not None and run.lease_owner == self.owner else None

    def fence(self, run_id: str, stop: RunStop) -> Fence:
        return lease_fence(run_id, stop, owner=self.owner, lease_s=self._lease_s)

    def event_detail(self) -> dict[str, Any]:
        return {"worker": self.owner}

    def finished(self, run_id: str, stop: RunStop) -> None:
        if not stop.lease_lost.is_set():
            self._release(run_id)

    # -- claim, renew, take over --------------------------------------------------------

    def _start_claimed(self, run_id: str) -> None:
        if not self.slots.start(run_id):  # closing: hand the run straight back
            self._release(run_id)

    def _poll(self) -> list[str]:
        """Reap expired leases, then claim up to the free slots; returns resumed run ids."""
        with transaction(self._sessions) as session:
            for run, previous in leases.expired_running(session=session):
                lifecycle.move(
                    session,
                    run,
                    RunStatus.INTERRUPTED,
                    event=EventKind.INTERRUPTED,
                    detail={
                        "reason": f"the lease of {previous or 'no process'} "
                        "expired: the process running it stopped",
                        "lease_owner": previous,
                        "worker": self.owner,
                    },
                )
        statuses = (
            [RunStatus.QUEUED, RunStatus.INTERRUPTED]
            if self._settings.auto_resume
            else [RunStatus.QUEUED]
        )
        with self._claim_lock:
            with transaction(self._sessions) as session:
                claimed = leases.claim_runs(
                    session=session,
                    owner=self.owner,
                    lease_s=self._lease_s,
                    limit=self.slots.free_slots(),
                    statuses=statuses,
                )
            for run_id, _ in claimed:
                self._start_claimed(run_id)
        if claimed:
            log.info("claimed %d run(s): %s", len(claimed), ", ".join(r for r, _ in claimed))
        return [run_id for run_id, status in claimed if status == RunStatus.INTERRUPTED]

    def _renew(self) -> None:
        held = self.slots.held()
        if not held:
            return
        with transaction(self._sessions) as session:
            alive = leases.renew(
                session=session, owner=self.owner, run_ids=list(held), lease_s=self._lease_s
            )
        for run_id, stop in held.items():
            if run_id not in alive:
                if not stop.lease_lost.is_set():
                    log.warning("lost the lease of run %s; stopping it here", run_id)
                stop.lease_lost.set()
            elif alive[run_id]:
                stop.cancelled.set()  # cancelled through another process

    def _release(self, run_id: str) -> None:
        with transaction(self._sessions) as session:
            leases.release(session=session, run_id=run_id, owner=self.owner)
