"""Liveness: is the service up, which version, what it can do."""

from __future__ import annotations

from fastapi import APIRouter, Request

from app.graph.version import current_version
from app.http.deps import SettingsDep
from app.operations.schemas import FleetBridgeOut, HealthOut
from app.solvers.registry import solver_names

router = APIRouter(tags=["health"])


# HEAD too: load balancers and container health checks often probe with it.
@router.api_route("/health", methods=["GET", "HEAD"], response_model=HealthOut)
def health(request: Request, settings: SettingsDep) -> HealthOut:
    """Report that the service is up, its version, solvers and default reasoner, and which
    process is the active fleet bridge."""
    # Read through its attributes: the fleet sits above operations (docs/development.md).
    bridge = getattr(request.app.state, "fleet", None)
    return HealthOut(
        fleet_bridge=(
            FleetBridgeOut.model_validate(bridge.role(), from_attributes=True)
            if bridge is not None
            else None
        ),
        version=request.app.version,
        graph_version=current_version(settings.test_graph_version),
        solvers=solver_names(),
        default_reasoner=settings.default_reasoner,
    )
