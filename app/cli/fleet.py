"""`ltaa fleet simulate` (docs/fleet.md#the-simulator): simulated VDA 5050 robots on a broker."""

from __future__ import annotations

from typing import Annotated

import typer

from app.cli.root import cli
from app.fleet.simulator import SimulatorConfig, simulate

fleet = typer.Typer(help="The robots' side of the fleet bridge (VDA 5050 over MQTT).")
cli.add_typer(fleet, name="fleet")


@fleet.command("simulate")
def simulate_command(
    url: Annotated[
        str, typer.Option(envvar="LTAA_MQTT_URL", help="The broker, mqtt://host:port")
    ] = "mqtt://127.0.0.1:1883",
    interface: Annotated[str, typer.Option(envvar="LTAA_MQTT_INTERFACE")] = "uagv",
    manufacturer: Annotated[str, typer.Option(envvar="LTAA_MQTT_MANUFACTURER")] = "ltaa-sim",
    robots: Annotated[int, typer.Option(min=1, max=1000, help="robot-1 .. robot-N")] = 3,
    names: Annotated[
        str | None, typer.Option(help="Comma-separated robot names (instead of --robots)")
    ] = None,
    speed: Annotated[
        float,
        typer.Option(
            min=0.001,
            help="Planned seconds a robot works through per second (600: a planned minute "
            "in 0.1 s)",
        ),
    ] = 1.0,
    fail_share: Annotated[float, typer.Option(min=0.0, max=1.0)] = 0.0,
    seed: Annotated[int, typer.Option()] = 0,
    default_duration_s: Annotated[
        float, typer.Option(min=0.0, help="An action's seconds when its order plans none")
    ] = 1.0,
    state_interval_s: Annotated[float, typer.Option(min=0.05)] = 1.0,
) -> None:
    """Simulated robots that take orders, report state every interval and at every change,
    fail a share of actions; stdin: `break NAME`, `offline NAME`, `quit` (its end ends the
    commands, not the robots: SIGTERM or SIGINT stops them)."""
    chosen = (
        tuple(n.strip() for n in names.split(",") if n.strip())
        if names
        else tuple(f"robot-{i + 1}" for i in range(robots))
    )
    simulate(
        SimulatorConfig(
            url=url,
            interface=interface,
            manufacturer=manufacturer,
            names=chosen,
            speed=speed,
            fail_share=fail_share,
            seed=seed,
            default_duration_s=default_duration_s,
            state_interval_s=state_interval_s,
        )
    )
