"""The application factory (served as `uvicorn app.asgi:create_app --factory`: app/asgi.py)."""

from __future__ import annotations

import importlib.metadata
import logging
import tomllib
from collections.abc import AsyncIterator
from contextlib import AsyncExitStack, asynccontextmanager
from functools import partial
from pathlib import Path

from fastapi import FastAPI
from fastapi.concurrency import run_in_threadpool
from sqlalchemy.orm import Session, sessionmaker

from app.api.drain import drain_on_signal
from app.api.openapi import install_openapi
from app.api.routers import body_limits, mount_routers
from app.config import Settings, get_settings
from app.console import install as install_console
from app.console.imports import CONSOLE_IMPORT_PATH
from app.fleet.bridge import Bridge
from app.fleet.metrics import FleetMetrics
from app.http.auth import InsecureBindError, KeyRing, check_bind
from app.http.errors import install_error_handlers
from app.http.middleware import BodySizeLimit, RequestMetrics
from app.http.rounding import RoundedJSONResponse
from app.observability.logs import configure_logging
from app.observability.metrics import Metrics, RunTablesCollector
from app.runs.deps import RunsContext
from app.runs.factory import make_worker
from app.runs.worker import RunWorker
from app.store.db import make_engine, make_session_factory
from app.store.lock import listen_url
from app.store.migrate import upgrade_head
from app.webhooks.deps import WebhooksContext
from app.webhooks.dispatcher import Dispatcher
from app.webhooks.metrics import WebhookTablesCollector
from app.webhooks.secret_box import SecretBox

log = logging.getLogger("ltaa")


def app_version() -> str:
    try:
        return importlib.metadata.version("ltaa")
    except importlib.metadata.PackageNotFoundError:
        # Running from a checkout that was never pip-installed: pyproject.toml is the truth.
        pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
        if pyproject.is_file():
            return str(tomllib.loads(pyproject.read_text())["project"]["version"])
        return "unknown"


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    settings: Settings = app.state.settings
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    _log_access_mode(settings, app.state.keyring)
    # Long-lived resources (database engine, checkpointer, run worker) are opened here and
    # register their cleanup on the stack, so shutdown closes them in reverse order even
    # when a later one fails to start.
    async with AsyncExitStack() as resources:
        app.state.resources = resources
        # Migrations before serving (idempotent; `make run` has applied them already).
        await run_in_threadpool(upgrade_head, settings.db_url)
        engine = make_engine(settings.db_url)
        resources.callback(engine.dispose)
        sessions = make_session_factory(engine)
        collector = RunTablesCollector(sessions)
        app.state.metrics.registry.register(collector)
        resources.callback(app.state.metrics.registry.unregister, collector)
        app.state.webhooks = _start_webhooks(settings, sessions, app.state.metrics, resources)
        worker = await run_in_threadpool(
            make_worker,
            settings=settings,
            sessions=sessions,
            serving=listen_url(settings.host, settings.port),
        )
        # Drain on shutdown: runs stop at a node boundary and are marked interrupted.
        resources.push_async_callback(run_in_threadpool, worker.close)
        # ... starting as soon as the signal arrives, before uvicorn waits on open streams.
        resources.enter_context(drain_on_signal(partial(_begin_drain, app, worker)))
        app.state.runs = RunsContext(sessions=sessions, worker=worker)
        app.state.fleet = await _start_fleet(
            settings, sessions, worker, app.state.metrics, resources
        )
        resumed = await run_in_threadpool(worker.recover)
        if resumed:
            log.info("resuming %d interrupted run(s): %s", len(resumed), ", ".join(resumed))
        yield


def _start_webhooks(
    settings: Settings,
    sessions: sessionmaker[Session],
    metrics: Metrics,
    resources: AsyncExitStack,
) -> WebhooksContext:
    secret_key = settings.secret_key.get_secret_value() if settings.secret_key else None
    box = SecretBox.from_setting(secret_key, settings.data_dir)
    collector = WebhookTablesCollector(sessions)
    metrics.registry.register(collector)
    resources.callback(metrics.registry.unregister, collector)
    dispatcher = None
    if settings.webhook_dispatch:
        # Off the request path: its own thread and pool. Closed before the engine (the
        # stack unwinds in reverse), after letting attempts in flight finish.
        dispatcher = Dispatcher(settings=settings, sessions=sessions, box=box)
        dispatcher.start()
        resources.callback(dispatcher.close)
    else:
        log.warning("webhook dispatch is off (LTAA_WEBHOOK_DISPATCH=false): deliveries wait")
    return WebhooksContext(sessions=sessions, box=box, dispatcher=dispatcher)


async def _start_fleet(
    settings: Settings,
    sessions: sessionmaker[Session],
    worker: RunWorker,
    metrics: Metrics,
    resources: AsyncExitStack,
) -> Bridge | None:
    """The VDA 5050 bridge (docs/fleet.md), when a broker is configured: active, or standing
    by while another process of the database is (docs/fleet.md#one-bridge-per-database).
    Started before serving (a run made from the first request on is on the fleet); closed
    before the worker (the stack unwinds in reverse), so no report arrives for a stopped
    worker."""
    if settings.mqtt_url is None:
        return None
    bridge = Bridge(
        settings=settings,
        sessions=sessions,
        worker=worker,
        metrics=FleetMetrics(metrics.registry),
    )
    await bridge.start()
    resources.push_async_callback(bridge.close)
    log.info("fleet bridge on: %s, interface %s", settings.mqtt_url, settings.mqtt_interface)
    return bridge


def _begin_drain(app: FastAPI, worker: RunWorker) -> None:
    bridge: Bridge | None = getattr(app.state, "fleet", None)
    if bridge is not None:  # its lease freed now: a standby takes over at once
        bridge.stand_down()
    held = worker.begin_drain()
    log.info(
        "shutting down: running runs stop at their next node boundary; %d run(s) "
        "continue at the next start",
        held,
    )


def _log_access_mode(settings: Settings, keyring: KeyRing) -> None:
    if keyring.open:
        log.warning(
            "access control is off: no API keys are configured (LTAA_API_KEYS), so "
            "every endpoint is open to anyone who can reach %s:%s. Allowed on "
            "loopback only; set LTAA_API_KEYS before listening elsewhere.",
            settings.host,
            settings.port,
        )
    else:
        log.info("access control on: API keys by role: %s", keyring.summary())


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or get_settings()
    configure_logging(settings)
    keyring = KeyRing.from_settings(settings)
    try:
        # Checked before anything is opened, so an exposed, keyless server never starts.
        check_bind(settings, keyring)
    except InsecureBindError as exc:
        log.critical("%s", exc)  # as a log line too, for whoever reads only the logs
        raise
    app = FastAPI(
        title="LTAA allocation service",
        summary="Phase-adaptive task allocation for heterogeneous construction robots",
        version=app_version(),
        lifespan=lifespan,
        default_response_class=RoundedJSONResponse,
    )
    app.state.settings = settings
    app.state.keyring = keyring
    app.state.metrics = Metrics()
    install_error_handlers(app)
    app.add_middleware(
        BodySizeLimit,
        max_bytes=settings.max_body_bytes,
        paths={
            **body_limits(settings),
            # The console's upload of a schedule file: the same limit as POST /schedules/import.
            CONSOLE_IMPORT_PATH: (settings.import_max_bytes, "LTAA_IMPORT_MAX_BYTES"),
        },
    )
    # Outermost, so rejected bodies (413) are timed too.
    app.add_middleware(RequestMetrics, histogram=app.state.metrics.request_seconds)
    mount_routers(app)
    install_openapi(app, open_access=keyring.open)
    install_console(app, keyring=keyring, settings=settings)
    return app
