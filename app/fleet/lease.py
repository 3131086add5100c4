"""One active fleet bridge per store (docs/fleet.md#one-bridge-per-database).

Every process with LTAA_MQTT_URL set starts a bridge; only the holder of the store's bridge
lease subscribes to the robots' state, dispatches and publishes the outbox. The lease is the
row of `fleet_bridge` (app.store.fleet_models.FleetBridge), timed by the database clock as a
run's lease is (app.store.leases), so processes on hosts with skewed clocks agree on when it
expired:

- Acquire: a lease that is free (never held, released, or expired by the database clock) is
  taken in one locked read-then-write; the holder takes the next `term` and writes the MQTT
  client id it connects under, and learns the one its predecessor used.
- Renew: every `lease_s / 4`, only while the row still names this process.
- Its own clock: a database row cannot stop an MQTT publish, so the holder publishes only
  until `PUBLISH_SHARE` of the lease has passed since it began its last successful renewal
  (its monotonic clock, started before the statement: the database's expiry is later still).
  A holder whose renewals stall stops publishing a third of a lease before any other process
  can take the lease over.
- Release: a graceful stop frees the row at once; a standby takes it at its next try.

The row is written by the first bridge that starts on the store, with `since`: now, or, on a
store whose bridge sent orders before the row existed, when the first lineage it sent was made.

On SQLite one process owns the store (app.store.lock.StoreLock proves it): `LocalLease` is
always held and never expires, and the row only records the client id and `since`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Protocol

from sqlalchemy import func, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.runs.factory import uses_leases
from app.store.db import transaction
from app.store.fleet_models import FleetBridge, FleetOrder
from app.store.leases import lease_owner_id
from app.store.models import Run, as_utc, utcnow

ROW = "bridge"
PUBLISH_SHARE = 2 / 3  # of a lease, after the start of its last renewal, the holder publishes
RENEWALS_PER_LEASE = 4
SHORTEST_WAIT_S = 0.05


@dataclass(frozen=True)
class Holding:
    """A term as the active bridge."""

    term: int
    client_id: str  # the MQTT client id this holder connects under
    previous_client_id: str  # the one the last holder connected under (its echo to drain)


@dataclass(frozen=True)
class Standing:
    """What the store's bridge row says: who holds the bridge now (None: nobody), since when
    the store has a fleet, and the client id its bridge last connected under."""

    holder: str | None
    since: datetime
    client_id: str


class Lease(Protocol):
    owner: str  # this process, as the row names it
    renew_every_s: float | None  # None: never needs renewing

    def prepare(self, client_id: str) -> Standing:
        """The store's bridge row, written with `client_id` and `since` = now if missing."""

    def acquire(self, client_id: str | None) -> Holding | None:
        """Take the bridge if it is free, connecting under `client_id` (None: the id the last
        holder used); None if another process holds it."""

    def renew(self) -> bool:
        """Extend the lease; False once another process took it."""

    def release(self) -> None: ...

    def may_publish(self) -> bool:
        """Whether this process's own clock says its lease still holds, with margin."""

    def publish_left_s(self) -> float:
        """Seconds until `may_publish` turns False unless the lease is renewed."""

    def retry_in_s(self) -> float:
        """How long a standby waits before trying to acquire again."""

    def fence(self, session: Session) -> bool:
        """Inside a write's transaction: this process still holds the lease (the row stays
        locked until commit)."""

    def standing(self) -> Standing: ...


def make_lease(settings: Settings, sessions: sessionmaker[Session]) -> Lease:
    if uses_leases(settings.db_url):
        return DatabaseLease(settings=settings, sessions=sessions)
    return LocalLease(settings=settings, sessions=sessions)


def _row(session: Session, *, lock: bool = False) -> FleetBridge:
    row = session.get(FleetBridge, ROW, with_for_update=lock)
    if row is None:
        raise RuntimeError("the fleet bridge's row is missing: Lease.prepare writes it first")
    return row


def _prepare(sessions: sessionmaker[Session], client_id: str) -> Standing:
    for _ in range(2):  # two processes creating the row at once: the loser reads the winner's
        try:
            with transaction(sessions) as session:
                row = session.get(FleetBridge, ROW)
                if row is None:
                    since = _first_sent(session) or utcnow()
                    row = FleetBridge(name=ROW, term=0, client_id=client_id, since=since)
                    session.add(row)
                    session.flush()
                holder = row.holder if row.holder and _live(session, row) else None
                return Standing(holder, as_utc(row.since), row.client_id)
        except IntegrityError:
            continue
    raise RuntimeError("could not write the fleet bridge's row")


def _first_sent(session: Session) -> datetime | None:
    """A store whose bridge sent orders before it had this row (an upgrade): its fleet began
    with the first lineage it sent, so every plan it was serving goes on being served."""
    first = session.scalar(
        select(func.min(Run.created_at)).join(FleetOrder, FleetOrder.lineage == Run.id)
    )
    return as_utc(first) if first is not None else None


def _live(session: Session, row: FleetBridge) -> bool:
    if row.expires_at is None:  # held with no expiry: the single SQLite process
        return row.holder is not None
    now = session.scalar(select(func.now()))
    return now is not None and as_utc(row.expires_at) > as_utc(now)


class LocalLease:
    """The single process of an SQLite store: always the holder."""

    renew_every_s: float | None = None

    def __init__(self, *, settings: Settings, sessions: sessionmaker[Session]) -> None:
        self.owner = lease_owner_id(settings.worker_name)
        self._sessions = sessions

    def prepare(self, client_id: str) -> Standing:
        return _prepare(self._sessions, client_id)

    def acquire(self, client_id: str | None) -> Holding | None:
        with transaction(self._sessions) as session:
            row = _row(session, lock=True)
            previous = row.client_id
            row.term += 1
            row.holder, row.expires_at = self.owner, None
            row.client_id = client_id or previous
            return Holding(row.term, row.client_id, previous)

    def renew(self) -> bool:
        return True

    def release(self) -> None:
        with transaction(self._sessions) as session:
            session.execute(
                update(FleetBridge)
                .where(FleetBridge.name == ROW, FleetBridge.holder == self.owner)
                .values(holder=None)
            )

    def may_publish(self) -> bool:
        return True

    def publish_left_s(self) -> float:
        return math.inf

    def retry_in_s(self) -> float:
        return SHORTEST_WAIT_S

    def fence(self, session: Session) -> bool:
        return True

    def standing(self) -> Standing:
        with self._sessions() as session:
            row = _row(session)
            return Standing(row.holder, as_utc(row.since), row.client_id)


class DatabaseLease:
    """A process sharing a PostgreSQL store with others."""

    def __init__(self, *, settings: Settings, sessions: sessionmaker[Session]) -> None:
        self.owner = lease_owner_id(settings.worker_name)
        self._sessions = sessions
        self._lease_s = settings.mqtt_lease_s
        self._poll_s = settings.claim_poll_s
        self.renew_every_s: float | None = self._lease_s / RENEWALS_PER_LEASE
        self._term: int | None = None
        self._publish_until = 0.0  # time.monotonic()
        self._free_in_s = 0.0  # what the last failed acquisition saw left of the holder's lease

    def prepare(self, client_id: str) -> Standing:
        return _prepare(self._sessions, client_id)

    def acquire(self, client_id: str | None) -> Holding | None:
        began = time.monotonic()
        with transaction(self._sessions) as session:
            row = _row(session, lock=True)
            now = as_utc(session.execute(select(func.now())).scalar_one())
            if row.holder not in (None, self.owner) and row.expires_at is not None:
                left = (as_utc(row.expires_at) - now).total_seconds()
                if left >= 0:
                    self._free_in_s = left
                    return None
            previous = row.client_id
            row.term += 1
            row.holder = self.owner
            row.expires_at = now + timedelta(seconds=self._lease_s)
            row.client_id = client_id or previous
            holding = Holding(row.term, row.client_id, previous)
        self._term = holding.term
        self._publish_until = began + self._lease_s * PUBLISH_SHARE
        return holding

    def renew(self) -> bool:
        began = time.monotonic()
        with transaction(self._sessions) as session:
            renewed = session.execute(
                update(FleetBridge)
                .where(
                    FleetBridge.name == ROW,
                    FleetBridge.holder == self.owner,
                    FleetBridge.term == self._term,
                )
                .values(expires_at=func.now() + timedelta(seconds=self._lease_s))
                .returning(FleetBridge.term)
                .execution_options(synchronize_session=False)
            ).first()
        if renewed is None:
            self._publish_until = 0.0
            return False
        self._publish_until = began + self._lease_s * PUBLISH_SHARE
        return True

    def release(self) -> None:
        self._publish_until = 0.0
        with transaction(self._sessions) as session:
            session.execute(
                update(FleetBridge)
                .where(FleetBridge.name == ROW, FleetBridge.holder == self.owner)
                .values(holder=None, expires_at=None)
                .execution_options(synchronize_session=False)
            )

    def may_publish(self) -> bool:
        return time.monotonic() < self._publish_until

    def publish_left_s(self) -> float:
        return self._publish_until - time.monotonic()

    def retry_in_s(self) -> float:
        # Wake as the holder's lease runs out (a dead holder is replaced at once), and look
        # again at least every claim_poll_s (a released lease is taken at the next look).
        return max(SHORTEST_WAIT_S, min(self._poll_s, self._free_in_s + SHORTEST_WAIT_S))

    def fence(self, session: Session) -> bool:
        held = session.scalar(
            select(FleetBridge.name)
            .where(
                FleetBridge.name == ROW,
                FleetBridge.holder == self.owner,
                FleetBridge.term == self._term,
                FleetBridge.expires_at > func.now(),
            )
            .with_for_update(read=True)
        )
        return held is not None

    def standing(self) -> Standing:
        with self._sessions() as session:
            row = _row(session)
            holder = row.holder if row.holder and _live(session, row) else None
            return Standing(holder, as_utc(row.since), row.client_id)
