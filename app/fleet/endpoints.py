"""The fleet as the bridge sees it (docs/fleet.md#the-robots)."""

from __future__ import annotations

from fastapi import APIRouter, Request

from app.fleet import service
from app.fleet.bridge import Bridge
from app.fleet.schemas import FleetOut, FleetRobotOut
from app.http.deps import ClientDep, SettingsDep
from app.http.responses import CLIENT, errors
from app.runs.deps import RunsDep

router = APIRouter(prefix="/fleet", tags=["fleet"])


@router.get("/robots", response_model=FleetOut, responses=errors(*CLIENT))
def list_robots(
    caller: ClientDep, runs: RunsDep, settings: SettingsDep, request: Request
) -> FleetOut:
    """Every robot that has sent the bridge a VDA 5050 `connection`: its connection, battery,
    FATAL error and open orders; and which process is the active bridge."""
    bridge: Bridge | None = getattr(request.app.state, "fleet", None)
    role = bridge.role() if bridge is not None else None
    return FleetOut(
        enabled=bridge is not None,
        active=role is not None and role.active,
        holder=role.holder if role is not None else None,
        connected=bridge is not None and bridge.connected.is_set(),
        interface=settings.mqtt_interface,
        robots=[
            FleetRobotOut.model_validate(r, from_attributes=True)
            for r in service.robots(sessions=runs.sessions)
        ],
    )
