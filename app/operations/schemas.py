"""Answer bodies of the service's own endpoints (health)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field


class FleetBridgeOut(BaseModel):
    """Which process is the database's active fleet bridge
    (docs/fleet.md#one-bridge-per-database)."""

    active: bool = Field(description="Whether this process is")
    holder: str | None = Field(description="The process that is; null while none is")
    this_process: str = Field(description="This process, as the bridge's lease names it")


class HealthOut(BaseModel):
    status: Literal["ok"] = "ok"
    version: str
    graph_version: str = Field(
        description="The graph version runs start under here (app.graph.version); a run "
        "interrupted under another resumes only under that one"
    )
    solvers: list[str]
    default_reasoner: str
    fleet_bridge: FleetBridgeOut | None = Field(
        None, description="The fleet bridge, when LTAA_MQTT_URL is set; null otherwise"
    )
