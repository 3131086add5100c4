"""The fleet's rows (docs/fleet.md): the robots the bridge has heard from, the orders it sent,
and its outbox of messages for the broker.

An order row and its outbox message are written in one transaction, and the outbox keeps each
message until the broker acknowledged it: a server killed between the two sends what was
committed when it starts again, and nothing that was not. headerIds count per topic in a row of
their own, so they keep increasing across restarts, as VDA 5050 asks.
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import DateTime, Float, Index, Integer, String, Text, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column

from app.domain.models import MAX_NAME_CHARS
from app.store.models import Base, utcnow


class FleetRobot(Base):
    """A vehicle as it last described itself: its connection, battery and the newest headerId
    and timestamp accepted per topic (replays and messages from the past are refused)."""

    __tablename__ = "fleet_robots"

    manufacturer: Mapped[str] = mapped_column(String(MAX_NAME_CHARS), primary_key=True)
    serial_number: Mapped[str] = mapped_column(String(MAX_NAME_CHARS), primary_key=True)
    connection: Mapped[str] = mapped_column(String(32))
    battery_charge: Mapped[float | None] = mapped_column(Float, nullable=True)
    charging: Mapped[bool | None] = mapped_column(nullable=True)
    # The error type of a FATAL error the robot reports (null when it reports none).
    fatal: Mapped[str | None] = mapped_column(String(200), nullable=True)
    state_header_id: Mapped[int | None] = mapped_column(Integer, nullable=True)
    state_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    connection_header_id: Mapped[int | None] = mapped_column(Integer, nullable=True)
    connection_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    updated_at: Mapped[datetime] = mapped_column(
        DateTime(timezone=True), default=utcnow, onupdate=utcnow
    )


class FleetOrder(Base):
    """One VDA 5050 order: a task of a lineage for one robot (a team task: one per member)."""

    __tablename__ = "fleet_orders"
    __table_args__ = (
        UniqueConstraint("lineage", "task_id", "robot", name="uq_fleet_orders_lineage_task_robot"),
        Index("ix_fleet_orders_robot_state", "manufacturer", "serial_number", "state"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    order_id: Mapped[str] = mapped_column(String(700), unique=True)
    lineage: Mapped[str] = mapped_column(String(32), index=True)  # the lineage's root run
    run_id: Mapped[str] = mapped_column(String(32))  # the head it was last sent for
    task_index: Mapped[int] = mapped_column(Integer)
    task_id: Mapped[str] = mapped_column(String(MAX_NAME_CHARS))
    robot: Mapped[str] = mapped_column(String(MAX_NAME_CHARS))
    manufacturer: Mapped[str] = mapped_column(String(MAX_NAME_CHARS))
    serial_number: Mapped[str] = mapped_column(String(MAX_NAME_CHARS))
    update_id: Mapped[int] = mapped_column(Integer, default=0)
    planned_start: Mapped[float | None] = mapped_column(Float, nullable=True)
    planned_end: Mapped[float | None] = mapped_column(Float, nullable=True)
    state: Mapped[str] = mapped_column(String(16))  # app.fleet.states.OrderState
    action_status: Mapped[str | None] = mapped_column(String(16), nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(
        DateTime(timezone=True), default=utcnow, onupdate=utcnow
    )


class FleetOutbox(Base):
    """A message for the broker, kept until the broker acknowledged it (QoS 1) or the bridge
    saw it come back from the broker (docs/fleet.md#delivery)."""

    __tablename__ = "fleet_outbox"
    __table_args__ = (UniqueConstraint("topic", "header_id", name="uq_fleet_outbox_topic_header"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    topic: Mapped[str] = mapped_column(String(1000))
    header_id: Mapped[int] = mapped_column(Integer)  # the message's, unique per topic
    payload: Mapped[str] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    published_at: Mapped[datetime | None] = mapped_column(
        DateTime(timezone=True), nullable=True, index=True
    )


class FleetHeader(Base):
    """The last headerId the bridge used on a topic."""

    __tablename__ = "fleet_headers"

    topic: Mapped[str] = mapped_column(String(1000), primary_key=True)
    last: Mapped[int] = mapped_column(Integer)


class FleetBridge(Base):
    """The one active bridge of the store (docs/fleet.md#one-bridge-per-database): a lease by the
    database clock, as a run's (app.store.leases), the MQTT client id the holder connects
    under, and when the store's fleet began (plans older than that are not sent)."""

    __tablename__ = "fleet_bridge"

    name: Mapped[str] = mapped_column(String(32), primary_key=True)
    holder: Mapped[str | None] = mapped_column(String(128), nullable=True)
    expires_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    # Counts the holders: each acquisition takes the next term.
    term: Mapped[int] = mapped_column(Integer, default=0)
    # The client id the last holder connected under (its echo session's is `{client_id}-echo`):
    # a new holder with another id drains that session first.
    client_id: Mapped[str] = mapped_column(String(64))
    since: Mapped[datetime] = mapped_column(DateTime(timezone=True))
