"""Bodies of the /fleet endpoints (docs/fleet.md#the-robots): the robots the bridge has heard
from, as their last messages describe them."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from app.http.times import Timestamp


class FleetRobotOut(BaseModel):
    # Built from the robot's row (app.store.fleet_models.FleetRobot): one shape, no copy.
    model_config = ConfigDict(from_attributes=True)

    manufacturer: str
    serial_number: str = Field(description="The robot's name on the site's runs")
    connection: str = Field(description="ONLINE, OFFLINE or CONNECTIONBROKEN (VDA 5050)")
    battery_charge: float | None = Field(description="Percent, from its last state")
    charging: bool | None
    fatal: str | None = Field(description="The type of a FATAL error it reports, else null")
    open_orders: int = Field(0, description="Orders sent and not finished, failed or cancelled")
    updated_at: Timestamp


class FleetOut(BaseModel):
    enabled: bool = Field(description="Whether the bridge runs (LTAA_MQTT_URL is set)")
    active: bool = Field(
        False,
        description="Whether this process is the database's active bridge (one at a time; "
        "the others stand by)",
    )
    holder: str | None = Field(
        None,
        description="The process that is the active bridge (its worker name, pid and a token); "
        "null while none is",
    )
    connected: bool = Field(
        description="Whether this process's bridge holds a connection to the broker (the "
        "active bridge does; a standby holds none)"
    )
    interface: str
    robots: list[FleetRobotOut]
