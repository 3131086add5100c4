"""What the /fleet endpoints and the console read (docs/fleet.md#the-robots)."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from app.fleet.states import OrderState
from app.store.fleet_models import FleetOrder, FleetRobot


@dataclass(frozen=True)
class RobotView:
    manufacturer: str
    serial_number: str
    connection: str
    battery_charge: float | None
    charging: bool | None
    fatal: str | None
    open_orders: int
    updated_at: object


def robots(*, sessions: sessionmaker[Session]) -> list[RobotView]:
    with sessions() as session:
        open_orders = dict(
            session.execute(
                select(FleetOrder.serial_number, func.count())
                .where(FleetOrder.state == OrderState.SENT)
                .group_by(FleetOrder.serial_number)
            ).all()
        )
        rows = session.scalars(
            select(FleetRobot).order_by(FleetRobot.manufacturer, FleetRobot.serial_number)
        )
        return [
            RobotView(
                r.manufacturer,
                r.serial_number,
                r.connection,
                r.battery_charge,
                r.charging,
                r.fatal,
                int(open_orders.get(r.serial_number, 0)),
                r.updated_at,
            )
            for r in rows
        ]
