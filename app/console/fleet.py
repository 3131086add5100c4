"""GET /console/fleet (docs/fleet.md#the-robots): the robots the fleet bridge has heard from, with
their connection, battery and open orders, and which process is the active bridge
(docs/fleet.md#one-bridge-per-database)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from app.console.context import ConsoleDep, SignedInDep, finish, sessions_of
from app.fleet import service

router = APIRouter(prefix="/console", include_in_schema=False)


@router.get("/fleet")
async def fleet_page(request: Request, console: ConsoleDep, signed: SignedInDep) -> Response:
    robots = await run_in_threadpool(service.robots, sessions=sessions_of(request))
    bridge = getattr(request.app.state, "fleet", None)
    role = await run_in_threadpool(bridge.role) if bridge is not None else None
    context = {
        "title": "Fleet",
        "robots": robots,
        "enabled": bridge is not None,
        "role": role,
        "connected": bridge is not None and bridge.connected.is_set(),
    }
    return finish(request, console.render(request, "fleet.html", context, signed=signed))
