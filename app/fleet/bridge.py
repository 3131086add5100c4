"""The fleet bridge (docs/fleet.md): one MQTT client beside the server, started by the app's
lifespan when LTAA_MQTT_URL is set.

It subscribes to every robot's `state` and `connection` under the interface, hands each
message to the `Intake` (in one worker thread: the store's writes stay in order), runs
`dispatch` after every message that changed something and every `tick_s`, and publishes the
outbox at QoS 1, marking each message once the broker acknowledged it. A lost broker is
retried with backoff; the outbox keeps what was not acknowledged.
"""

from __future__ import annotations

import asyncio
import hashlib
import logging
import socket
from concurrent.futures import ThreadPoolExecutor
from contextlib import suppress
from urllib.parse import urlsplit

import aiomqtt
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.fleet import outbox
from app.fleet.dispatch import FleetNames, dispatch
from app.fleet.echo import EchoSession
from app.fleet.intake import Intake
from app.fleet.metrics import FleetMetrics
from app.fleet.vda5050 import Topic, subscription
from app.runs.worker import RunWorker

log = logging.getLogger("ltaa.fleet")


def names_of(settings: Settings) -> FleetNames:
    return FleetNames(
        interface=settings.mqtt_interface,
        manufacturer=settings.mqtt_manufacturer,
        sites=FleetNames.parse_sites(settings.mqtt_sites),
    )


def default_client_id(settings: Settings) -> str:
    """ltaa-{host}-{store}: stable across restarts of one server (its echo session is found
    again), distinct for two servers on one machine (a broker drops the older of two clients
    with one id)."""
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
        tick_s: float = 0.5,
    ) -> None:
        if settings.mqtt_url is None:
            raise ValueError("the fleet bridge needs LTAA_MQTT_URL")
        url = urlsplit(settings.mqtt_url)
        self.host = url.hostname or "127.0.0.1"
        self.port = url.port or (8883 if url.scheme == "mqtts" else 1883)
        self.tls = url.scheme == "mqtts"
        self.identifier = settings.mqtt_client_id or default_client_id(settings)
        self.sessions = sessions
        self.names = names_of(settings)
        self.metrics = metrics
        self.tick_s = tick_s
        self._wake = asyncio.Event()
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ltaa-fleet")
        self.intake = Intake(
            sessions=sessions,
            worker=worker,
            settings=settings,
            names=self.names,
            metrics=metrics,
        )
        self._task: asyncio.Task[None] | None = None
        self.connected = asyncio.Event()
        self.echo = EchoSession(
            host=self.host,
            port=self.port,
            tls=self.tls,
            identifier=f"{self.identifier}-echo"[:64],
            interface=self.names.interface,
            sessions=sessions,
        )

    def start(self) -> None:
        self.echo.start()
        self._task = asyncio.get_running_loop().create_task(self._run(), name="ltaa-fleet")

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with suppress(asyncio.CancelledError):
                await self._task
        self.echo.close()
        self._pool.shutdown(wait=True)

    async def _in_thread(self, fn, *args, **kwargs):  # type: ignore[no-untyped-def]
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._pool, lambda: fn(*args, **kwargs))

    def _client(self, identifier: str, *, clean: bool) -> aiomqtt.Client:
        return aiomqtt.Client(
            self.host,
            self.port,
            identifier=identifier,
            tls_params=aiomqtt.TLSParameters() if self.tls else None,
            keepalive=30,
            clean_session=clean,
        )

    async def _run(self) -> None:
        delay = 0.5
        while True:
            try:
                async with self._client(self.identifier, clean=True) as client:
                    delay = 0.5
                    log.info("fleet bridge connected to %s:%s", self.host, self.port)
                    for kind in (Topic.CONNECTION, Topic.STATE):
                        await client.subscribe(subscription(self.names.interface, kind), qos=1)
                    self.connected.set()
                    await self._serve(client)
            except aiomqtt.MqttError as exc:
                self.connected.clear()
                log.warning("fleet bridge lost the broker (%s); retrying in %.1f s", exc, delay)
                await asyncio.sleep(delay)
                delay = min(delay * 2, 10.0)

    async def _serve(self, client: aiomqtt.Client) -> None:
        async with asyncio.TaskGroup() as group:
            group.create_task(self._publish(client))
            group.create_task(self._tick())
            async for message in client.messages:
                payload = message.payload
                data = payload if isinstance(payload, bytes) else str(payload).encode()
                try:
                    await self._in_thread(
                        self.intake.receive, str(message.topic), data, retained=bool(message.retain)
                    )
                except Exception:  # one message must not stop the others (docs/fleet.md)
                    log.exception("fleet bridge could not apply a message on %s", message.topic)
                if self.intake.take_changed():
                    self._wake.set()

    async def _tick(self) -> None:
        while True:
            await asyncio.sleep(self.tick_s)
            self._wake.set()

    async def _publish(self, client: aiomqtt.Client) -> None:
        """Dispatch, then send the outbox in order, each message marked once acknowledged.
        First, what the echo session holds from before a kill is marked (app.fleet.echo)."""
        loop = asyncio.get_running_loop()
        if not await loop.run_in_executor(None, self.echo.caught_up.wait, 30.0):
            log.warning("fleet bridge: the echo session did not catch up; publishing anyway")
        while True:
            await self._wake.wait()
            self._wake.clear()
            try:
                if await self._in_thread(dispatch, sessions=self.sessions, names=self.names):
                    # On the intake's own thread, never in the middle of a message.
                    await self._in_thread(self.intake.orders_changed)
            except Exception:  # a bad plan must not stop the robots' messages
                log.exception("fleet dispatch failed; trying again at the next message")
            while True:
                batch = await self._in_thread(outbox.pending, sessions=self.sessions)
                if not batch:
                    break
                for item in batch:
                    await client.publish(item.topic, item.payload, qos=1, timeout=30)
                    self.metrics.sent(item.topic.rsplit("/", 1)[-1])
                    await self._in_thread(
                        outbox.mark_published, sessions=self.sessions, ids=[item.id]
                    )
