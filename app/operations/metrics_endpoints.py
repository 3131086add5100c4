"""GET /metrics: Prometheus text exposition."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

from app.http.deps import SupervisorDep
from app.http.responses import SUPERVISOR, errors
from app.observability.metrics import Metrics

router = APIRouter(tags=["metrics"])


@router.get(
    "/metrics",
    response_class=Response,
    responses={
        200: {"content": {CONTENT_TYPE_LATEST: {}}, "description": "Prometheus text format"},
        **errors(*SUPERVISOR),
    },
)
def metrics(request: Request, caller: SupervisorDep) -> Response:
    """For supervisors (and the Prometheus scraper): runs, decisions, LLM usage, validation,
    retries, fallbacks and request latency."""
    # A plain `def`: the run counts are database queries, kept off the event loop.
    app_metrics: Metrics = request.app.state.metrics
    return Response(generate_latest(app_metrics.registry), media_type=CONTENT_TYPE_LATEST)
