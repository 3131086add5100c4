"""The JSON API's routers, one per feature package, in the order the app mounts them (the
OpenAPI document lists paths in this order), and the request bodies that have a limit of
their own."""

from __future__ import annotations

from functools import partial

from fastapi import APIRouter, FastAPI

from app.allocation import catalog_endpoints
from app.allocation import endpoints as allocation
from app.audit import endpoints as audit
from app.audit.signing import SigningKeys
from app.config import Settings
from app.fleet import endpoints as fleet
from app.operations import endpoints as operations
from app.operations import health_endpoints, metrics_endpoints
from app.plans import endpoints as plans
from app.reviews import endpoints as reviews
from app.reviews import signoff_endpoints
from app.runs import endpoints as runs
from app.runs import event_endpoints
from app.schedules import endpoints as schedules
from app.schedules import import_endpoints
from app.sites import endpoints as sites
from app.webhooks import endpoints as webhooks

ROUTERS: tuple[APIRouter, ...] = (
    health_endpoints.router,
    catalog_endpoints.router,
    allocation.router,
    runs.router,
    schedules.router,
    plans.router,
    signoff_endpoints.router,
    reviews.router,
    event_endpoints.router,
    metrics_endpoints.router,
    webhooks.router,
    sites.router,
    fleet.router,
    operations.router,
    audit.router,
    import_endpoints.router,
)


def mount_routers(app: FastAPI) -> None:
    for router in ROUTERS:
        app.include_router(router)
    # GET /audit/public-key: the run worker's signing keys, which app.audit may not read
    # itself (app.audit.endpoints.SigningKeysSource).
    app.state.signing_keys = partial(_signing_keys, app)


def _signing_keys(app: FastAPI) -> SigningKeys:
    keys: SigningKeys = app.state.runs.worker.signing_keys
    return keys


def body_limits(settings: Settings) -> dict[str, tuple[int, str]]:
    """Path -> (its body limit in bytes, the setting that raises it), for the paths whose
    bodies may be larger than LTAA_MAX_BODY_BYTES (an imported schedule file)."""
    return {import_endpoints.IMPORT_PATH: (settings.import_max_bytes, "LTAA_IMPORT_MAX_BYTES")}
