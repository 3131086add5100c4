"""The fleet bridge (docs/fleet.md): MQTT clients beside the server, started by the app's lifespan
when LTAA_MQTT_URL is set; one process of a database is the active bridge at a time.

Every process starts a bridge, and the bridge stands by until it holds the store's bridge lease
(app.fleet.lease; docs/fleet.md#one-bridge-per-database). Then, for as long as it holds it:

- its echo session connects under the active bridge's id (and, after a holder that connected
  under another id, drains that one's session first): what the last holder published and did
  not mark is marked before anything is sent (app.fleet.echo);
- its client subscribes to every robot's `state` and `connection` under the interface and
  hands each message to a fresh `Intake` (in one worker thread: the store's writes stay in
  order);
- it runs `dispatch` (fenced by the lease, in the same transaction) after every message that
  changed something and every `tick_s`, and publishes the outbox at QoS 1, marking each
  message once the broker acknowledged it, and only while its own clock says the lease holds.

A lost broker is retried with backoff; the outbox keeps what was not acknowledged. A lease
that could not be renewed in time, or that another process took, ends the term: the clients
disconnect and the bridge stands by again.
"""

from __future__ import annotations

import asyncio
import hashlib
import logging
import socket
from concurrent.futures import ThreadPoolExecutor
from contextlib import suppress
from dataclasses import dataclass, replace
from typing import Any
from urllib.parse import urlsplit

import aiomqtt
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.fleet import outbox
from app.fleet.dispatch import FleetNames, dispatch
from app.fleet.echo import EchoSession, forget_session
from app.fleet.intake import Intake
from app.fleet.lease import Holding, Lease, make_lease
from app.fleet.metrics import FleetMetrics
from app.fleet.vda5050 import Topic, subscription
from app.runs.worker import RunWorker

log = logging.getLogger("ltaa.fleet")

ECHO_CATCH_UP_S = 30.0


class LeaseLost(Exception):
    """This process is no longer the active bridge (the message says why)."""


@dataclass(frozen=True)
class Role:
    """Which process holds the bridge, as GET /fleet/robots and /health say it."""

    active: bool  # this process is the active bridge
    holder: str | None  # the process that is (None: none holds it now)
    this_process: str


def names_of(settings: Settings) -> FleetNames:
    return FleetNames(
        interface=settings.mqtt_interface,
        manufacturer=settings.mqtt_manufacturer,
        sites=FleetNames.parse_sites(settings.mqtt_sites),
    )


def default_client_id(settings: Settings) -> str:
    """The id a store's first bridge writes to its row, then every holder's unless
    LTAA_MQTT_CLIENT_ID says otherwise: ltaa-{host}-{store}, what a bridge used before the
    store had a row (its echo session is found again after an upgrade)."""
    store = hashlib.sha256(settings.db_url.encode()).hexdigest()[:8]
    return f"ltaa-{socket.gethostname()[:40]}-{store}"


class Bridge:
    def __init__(
        self,
        *,
        settings: Settings,
        sessions: sessionmaker[Session],
        worker: RunWorker,
        metrics: FleetMetrics,
        lease: Lease | None = None,
        tick_s: float = 0.5,
    ) -> None:
        if settings.mqtt_url is None:
            raise ValueError("the fleet bridge needs LTAA_MQTT_URL")
        url = urlsplit(settings.mqtt_url)
        self.host = url.hostname or "127.0.0.1"
        self.port = url.port or (8883 if url.scheme == "mqtts" else 1883)
        self.tls = url.scheme == "mqtts"
        self.settings = settings
        self.sessions = sessions
        self.worker = worker
        self.names = names_of(settings)
        self.metrics = metrics
        self.tick_s = tick_s
        self.lease = lease or make_lease(settings, sessions)
        self.active = False
        self.connected = asyncio.Event()
        self._wake = asyncio.Event()
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ltaa-fleet")
        # The lease's own thread: a renewal never waits behind a message being applied.
        self._lease_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ltaa-fleet-lease")
        self._task: asyncio.Task[None] | None = None
        self._closing: asyncio.Task[None] | None = None

    # -- life ------------------------------------------------------------------------

    async def start(self) -> None:
        """Write the store's bridge row if it is new, then stand by or serve."""
        standing = await self._leased(self.lease.prepare, default_client_id(self.settings))
        self.names = replace(self.names, since=standing.since)
        self._task = asyncio.get_running_loop().create_task(self._run(), name="ltaa-fleet")

    def stand_down(self) -> None:
        """Shutdown begins (SIGTERM): stop serving and free the lease now, so a standby takes
        over at once rather than after the lease."""
        if self._closing is None:
            self._closing = asyncio.get_running_loop().create_task(self._stop())

    async def close(self) -> None:
        self.stand_down()
        assert self._closing is not None
        await self._closing
        self._pool.shutdown(wait=True)
        self._lease_pool.shutdown(wait=True)

    async def _stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with suppress(asyncio.CancelledError):
                await self._task
        try:  # after the clients disconnected: nothing is published after the release
            await self._leased(self.lease.release)
        except Exception:  # the lease then runs out by itself
            log.exception("fleet bridge: could not release its lease")

    def role(self) -> Role:
        if self.active:
            return Role(True, self.lease.owner, self.lease.owner)
        try:
            holder = self.lease.standing().holder
        except Exception:  # /health answers while the database is away
            log.exception("fleet bridge: could not read which process is the active bridge")
            holder = None
        return Role(False, holder, self.lease.owner)

    async def _in_thread(self, fn, *args, **kwargs):  # type: ignore[no-untyped-def]
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._pool, lambda: fn(*args, **kwargs))

    async def _leased(self, fn, *args):  # type: ignore[no-untyped-def]
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._lease_pool, fn, *args)

    # -- standing by, holding ----------------------------------------------------------

    async def _run(self) -> None:
        while True:
            try:
                holding = await self._leased(self.lease.acquire, self.settings.mqtt_client_id)
            except Exception:
                log.exception("fleet bridge: could not ask for the lease; trying again")
                holding = None
            if holding is None:
                await asyncio.sleep(self.lease.retry_in_s())
                continue
            log.info(
                "fleet bridge: %s is the active bridge (term %d, client id %s)",
                self.lease.owner,
                holding.term,
                holding.client_id,
            )
            self.active = True
            try:
                await self._hold(holding)
            except* LeaseLost as lost:
                log.warning(
                    "fleet bridge: %s stopped publishing and stands by: %s",
                    self.lease.owner,
                    _first(lost),
                )
            except* Exception:
                log.exception("fleet bridge: its term ended on an error; it stands by")
                await asyncio.sleep(self.tick_s)
            finally:
                self.active = False
                self.connected.clear()

    async def _hold(self, holding: Holding) -> None:
        echo = self._echo(f"{holding.client_id}-echo")
        echo.start()
        try:
            async with asyncio.TaskGroup() as group:
                group.create_task(self._keep(), name="ltaa-fleet-lease")
                group.create_task(self._connect(holding, echo), name="ltaa-fleet-mqtt")
        finally:
            echo.close()

    async def _keep(self) -> None:
        """Renew the lease every renew_every_s; raise LeaseLost when it is gone, or when a
        renewal did not come back before this process's own clock ran out."""
        every = self.lease.renew_every_s
        if every is None:
            await asyncio.Event().wait()  # never renewed, never lost
            return
        while True:
            await asyncio.sleep(every)
            try:
                async with asyncio.timeout(max(self.lease.publish_left_s(), 0.0)):
                    renewed = await self._leased(self.lease.renew)
            except TimeoutError:
                raise LeaseLost("its lease was not renewed in time") from None
            except Exception:
                log.exception("fleet bridge: could not renew its lease")
                if not self.lease.may_publish():
                    raise LeaseLost("its lease was not renewed in time") from None
                continue
            if not renewed:
                raise LeaseLost("another process holds the lease")

    # -- connected ---------------------------------------------------------------------

    def _echo(self, identifier: str) -> EchoSession:
        return EchoSession(
            host=self.host,
            port=self.port,
            tls=self.tls,
            identifier=identifier,
            interface=self.names.interface,
            sessions=self.sessions,
        )

    def _client(self, identifier: str) -> aiomqtt.Client:
        return aiomqtt.Client(
            self.host,
            self.port,
            identifier=identifier,
            tls_params=aiomqtt.TLSParameters() if self.tls else None,
            keepalive=30,
            clean_session=True,
        )

    async def _connect(self, holding: Holding, echo: EchoSession) -> None:
        intake = Intake(
            sessions=self.sessions,
            worker=self.worker,
            settings=self.settings,
            names=self.names,
            metrics=self.metrics,
        )
        await self._drain(holding)
        delay = 0.5
        while True:
            try:
                async with self._client(holding.client_id) as client:
                    delay = 0.5
                    log.info("fleet bridge connected to %s:%s", self.host, self.port)
                    for kind in (Topic.CONNECTION, Topic.STATE):
                        await client.subscribe(subscription(self.names.interface, kind), qos=1)
                    self.connected.set()
                    await self._serve(client, intake, echo)
            except* aiomqtt.MqttError as lost:
                self.connected.clear()
                log.warning(
                    "fleet bridge lost the broker (%s); retrying in %.1f s", _first(lost), delay
                )
                await asyncio.sleep(delay)
                delay = min(delay * 2, 10.0)

    async def _drain(self, holding: Holding) -> None:
        """A last holder that connected under another client id left its echo session: what
        it published and did not mark is marked from there, then the session is dropped."""
        if holding.previous_client_id == holding.client_id:
            return
        identifier = f"{holding.previous_client_id}-echo"
        drain = self._echo(identifier)
        drain.start()
        try:
            if not await asyncio.to_thread(drain.caught_up.wait, ECHO_CATCH_UP_S):
                log.warning("fleet bridge: the last holder's echo session did not catch up")
        finally:
            drain.close()
        await asyncio.to_thread(forget_session, self.host, self.port, self.tls, identifier)

    async def _serve(self, client: aiomqtt.Client, intake: Intake, echo: EchoSession) -> None:
        async with asyncio.TaskGroup() as group:
            group.create_task(self._publish(client, intake, echo))
            group.create_task(self._tick())
            async for message in client.messages:
                if not self.lease.may_publish():
                    raise LeaseLost("its lease ran out by its own clock")
                payload = message.payload
                data = payload if isinstance(payload, bytes) else str(payload).encode()
                try:
                    await self._in_thread(
                        intake.receive, str(message.topic), data, retained=bool(message.retain)
                    )
                except Exception:  # one message must not stop the others (docs/fleet.md)
                    log.exception("fleet bridge could not apply a message on %s", message.topic)
                if intake.take_changed():
                    self._wake.set()

    async def _tick(self) -> None:
        while True:
            await asyncio.sleep(self.tick_s)
            self._wake.set()

    async def _publish(self, client: aiomqtt.Client, intake: Intake, echo: EchoSession) -> None:
        """Dispatch, then send the outbox in order, each message marked once acknowledged.
        First, what the echo session holds from before a kill is marked (app.fleet.echo)."""
        if not await asyncio.to_thread(echo.caught_up.wait, ECHO_CATCH_UP_S):
            log.warning("fleet bridge: the echo session did not catch up; publishing anyway")
        while True:
            await self._wake.wait()
            self._wake.clear()
            await self._dispatch(intake)
            while True:
                batch = await self._in_thread(outbox.pending, sessions=self.sessions)
                if not batch:
                    break
                for item in batch:
                    # A row of the database cannot stop a publish: this process's clock does.
                    if not self.lease.may_publish():
                        raise LeaseLost("its lease ran out by its own clock")
                    await client.publish(item.topic, item.payload, qos=1, timeout=30)
                    self.metrics.sent(item.topic.rsplit("/", 1)[-1])
                    await self._in_thread(
                        outbox.mark_published, sessions=self.sessions, ids=[item.id]
                    )

    async def _dispatch(self, intake: Intake) -> None:
        try:
            fence = self.lease.fence
            if await self._in_thread(
                dispatch, sessions=self.sessions, names=self.names, fence=fence
            ):
                # On the intake's own thread, never in the middle of a message.
                await self._in_thread(intake.orders_changed)
        except Exception:  # a bad plan must not stop the robots' messages
            log.exception("fleet dispatch failed; trying again at the next message")


def _first(group: BaseExceptionGroup[Any]) -> BaseException:
    """The first exception a (nested) group holds: what a log line names."""
    first: BaseException = group
    while isinstance(first, BaseExceptionGroup):
        first = first.exceptions[0]
    return first
