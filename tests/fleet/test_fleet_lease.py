"""The fleet bridge's lease (docs/fleet.md#one-bridge-per-database), on a real PostgreSQL database
and, for the bridge itself, a real mosquitto:

- one holder at a time; a holder that stops renewing stops publishing by its own clock before
  the database lets another process take the lease, and is fenced out afterwards;
- a graceful release is taken over at once, and the new holder learns the client id its
  predecessor connected under;
- a bridge whose renewals stall (the database slow to answer it, the process starved) stops
  publishing its outbox before a standby takes the lease over;
- on SQLite the one process always holds it.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from prometheus_client import CollectorRegistry
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.fleet import outbox
from app.fleet.bridge import Bridge
from app.fleet.lease import PUBLISH_SHARE, DatabaseLease, Holding, LocalLease
from app.fleet.metrics import FleetMetrics
from app.fleet.vda5050 import (
    CANCEL_ORDER,
    PROTOCOL_VERSION,
    Action,
    InstantActions,
    Topic,
    topic,
)
from app.runs.factory import make_worker
from app.store.db import make_engine, make_session_factory, transaction
from app.store.migrate import upgrade_head
from app.store.models import utcnow
from tests.support.mqtt_broker import Recorder
from tests.support.polling import eventually
from tests.support.postgres import fresh_database

LEASE_S = 1.5


@pytest.fixture(scope="module")
def database() -> Iterator[str]:
    with fresh_database("ltaa_fleet_lease") as url:
        upgrade_head(url)
        yield url


@pytest.fixture
def sessions(database: str) -> Iterator[sessionmaker[Session]]:
    engine = make_engine(database)
    with engine.begin() as conn:  # each test starts with no bridge row
        conn.exec_driver_sql("DELETE FROM fleet_bridge")
        conn.exec_driver_sql("DELETE FROM fleet_outbox")
    yield make_session_factory(engine)
    engine.dispose()


def settings(database: str, name: str, **more: object) -> Settings:
    return Settings(
        database_url=database,
        worker_name=name,
        mqtt_lease_s=LEASE_S,
        claim_poll_s=0.1,
        **more,  # type: ignore[arg-type]
    )


def lease(database: str, sessions: sessionmaker[Session], name: str) -> DatabaseLease:
    return DatabaseLease(settings=settings(database, name), sessions=sessions)


def test_a_holder_that_stops_renewing_stops_publishing_before_another_takes_over(
    database: str, sessions: sessionmaker[Session]
) -> None:
    a, b = lease(database, sessions, "a"), lease(database, sessions, "b")
    a.prepare("id-a")
    holding = a.acquire("id-a")
    assert holding is not None and holding.client_id == "id-a"
    assert b.acquire("id-b") is None and b.standing().holder == a.owner
    assert a.renew() and a.may_publish()
    # a stops renewing: when does its own clock stop it, when may b take over?
    stopped = taken = None
    began = time.monotonic()
    while taken is None and time.monotonic() - began < 10 * LEASE_S:
        if stopped is None and not a.may_publish():
            stopped = time.monotonic()
        if b.acquire("id-b") is not None:
            taken = time.monotonic()
        time.sleep(0.01)
    assert stopped is not None and taken is not None
    margin = taken - stopped
    assert margin >= LEASE_S * (1 - PUBLISH_SHARE) * 0.5, f"stopped only {margin:.2f} s before"
    # Fenced out: a's renewal fails, its clock stays stopped, its writes' fence refuses.
    assert a.renew() is False and not a.may_publish()
    with sessions() as session:
        assert a.fence(session) is False
        assert b.fence(session) is True


def test_a_released_lease_is_taken_at_once_under_the_last_client_id(
    database: str, sessions: sessionmaker[Session]
) -> None:
    a, b = lease(database, sessions, "a"), lease(database, sessions, "b")
    first = a.prepare("id-first")
    assert b.prepare("id-other") == first  # the row is written once
    held = a.acquire(None)
    assert held is not None and held.client_id == "id-first"
    a.release()
    assert not a.may_publish() and b.standing().holder is None
    taken = b.acquire(None)
    assert taken is not None and taken.term == held.term + 1
    assert taken.client_id == taken.previous_client_id == "id-first"
    b.release()
    own = a.acquire("id-a")
    assert own is not None and (own.client_id, own.previous_client_id) == ("id-a", "id-first")


def test_on_sqlite_the_one_process_always_holds_it(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'app.db'}"
    upgrade_head(url)
    local = LocalLease(
        settings=Settings(database_url=url, worker_name="solo"),
        sessions=make_session_factory(make_engine(url)),
    )
    standing = local.prepare("id-solo")
    held = local.acquire(None)
    assert held is not None and held.client_id == "id-solo" and local.may_publish()
    assert local.renew_every_s is None and local.standing().holder == local.owner
    assert local.standing().since == standing.since


class StallingLease(DatabaseLease):
    """A real lease whose statements hang while `stalled` is set: the database slow to answer
    this process, or the process starved (a fault a real server cannot be made to show on
    demand)."""

    def __init__(self, *, settings: Settings, sessions: sessionmaker[Session]) -> None:
        super().__init__(settings=settings, sessions=sessions)
        self.stalled = threading.Event()
        self.resumed = threading.Event()

    def _stall(self) -> None:
        if self.stalled.is_set():
            self.resumed.wait(30)

    def renew(self) -> bool:
        self._stall()
        return super().renew()

    def acquire(self, client_id: str | None) -> Holding | None:
        self._stall()
        return super().acquire(client_id)


def _instant(sessions: sessionmaker[Session], interface: str, n: int) -> None:
    """An outbox row (a valid VDA 5050 instantActions) for the bridge to publish."""
    name = topic(interface, "ltaa-sim", "robot-1", Topic.INSTANT_ACTIONS)
    with transaction(sessions) as session:
        header = outbox.next_header_id(session, name)
        message = InstantActions(
            header_id=header,
            timestamp=utcnow(),
            version=PROTOCOL_VERSION,
            manufacturer="ltaa-sim",
            serial_number="robot-1",
            actions=[Action(action_type=CANCEL_ORDER, action_id=f"probe-{n}")],
        )
        outbox.enqueue(session, name, message)


def test_a_bridge_whose_renewals_stall_stops_publishing_before_a_standby_takes_over(
    database: str,
    sessions: sessionmaker[Session],
    mqtt_url: str,
    interface: str,
    recorder: Recorder,
    tmp_path: Path,
) -> None:
    config = settings(
        database,
        "stalled",
        mqtt_url=mqtt_url,
        mqtt_interface=interface,
        mqtt_client_id=f"{interface}-bridge",
        data_dir=tmp_path,
    )
    worker = make_worker(settings=config, sessions=sessions)
    stalling = StallingLease(settings=config, sessions=sessions)
    standby = lease(database, sessions, "standby")
    sent = 0

    def feed() -> None:
        nonlocal sent
        _instant(sessions, interface, sent)
        sent += 1

    async def scenario() -> tuple[float | None, float]:
        bridge = Bridge(
            settings=config,
            sessions=sessions,
            worker=worker,
            metrics=FleetMetrics(CollectorRegistry()),
            lease=stalling,
            tick_s=0.05,
        )
        await bridge.start()
        try:
            for _ in range(3):
                await asyncio.to_thread(feed)
            await asyncio.to_thread(
                eventually,
                lambda: len(recorder.of("instantActions")),
                until=lambda n: n == 3,
                what="the bridge publishing while it holds the lease",
            )
            stalling.stalled.set()
            stood_down = taken = None
            while taken is None:
                await asyncio.to_thread(feed)
                if stood_down is None and not bridge.active:
                    stood_down = time.monotonic()
                if await asyncio.to_thread(standby.acquire, "standby") is not None:
                    taken = time.monotonic()
                await asyncio.sleep(0.05)
            return stood_down, taken
        finally:
            stalling.resumed.set()
            await bridge.close()

    try:
        stood_down, taken = asyncio.run(scenario())
    finally:
        worker.close()
    arrivals = [m.at for m in recorder.of("instantActions")]
    assert recorder.invalid == []
    assert max(arrivals) < taken, "a message was published after another process took over"
    assert len(arrivals) < sent, "nothing was left to publish: the test proves nothing"
    assert stood_down is not None and stood_down < taken, "still active when it was taken over"
