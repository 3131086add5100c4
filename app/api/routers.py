"""The JSON API's routers, one per feature package, in the order the app mounts them (the
OpenAPI document lists paths in this order)."""

from __future__ import annotations

from fastapi import APIRouter

from app.allocation import catalog_endpoints
from app.allocation import endpoints as allocation
from app.operations import endpoints as operations
from app.operations import health_endpoints, metrics_endpoints
from app.plans import endpoints as plans
from app.plans import schedule_endpoints
from app.reviews import endpoints as reviews
from app.reviews import signoff_endpoints
from app.runs import audit_endpoints, event_endpoints
from app.runs import endpoints as runs
from app.sites import endpoints as sites
from app.webhooks import endpoints as webhooks

ROUTERS: tuple[APIRouter, ...] = (
    health_endpoints.router,
    catalog_endpoints.router,
    allocation.router,
    runs.router,
    schedule_endpoints.router,
    plans.router,
    signoff_endpoints.router,
    reviews.router,
    event_endpoints.router,
    metrics_endpoints.router,
    webhooks.router,
    sites.router,
    operations.router,
    audit_endpoints.router,
)
