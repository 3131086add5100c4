"""The fleet's outbox (docs/fleet.md#delivery): messages written with the order rows they
carry, published in order by the bridge and marked once the broker acknowledged them, or once
the bridge's echo session received them back (what closes the window of a kill between the
broker's acknowledgement and the mark)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

from app.fleet.vda5050 import Message
from app.store.db import transaction
from app.store.fleet_models import FleetHeader, FleetOutbox
from app.store.models import utcnow


@dataclass(frozen=True)
class Outgoing:
    id: int
    topic: str
    payload: bytes


def next_header_id(session: Session, topic: str) -> int:
    """The next headerId on the topic: 0, 1, 2, ... across restarts (VDA 5050 counts per topic)."""
    row = session.get(FleetHeader, topic, with_for_update=True)
    if row is None:
        session.add(FleetHeader(topic=topic, last=0))
        session.flush()
        return 0
    row.last += 1
    return row.last


def enqueue(session: Session, topic: str, message: Message) -> None:
    session.add(
        FleetOutbox(topic=topic, header_id=message.header_id, payload=message.wire().decode())
    )


def pending(*, sessions: sessionmaker[Session], limit: int = 200) -> list[Outgoing]:
    with sessions() as session:
        rows = session.scalars(
            select(FleetOutbox)
            .where(FleetOutbox.published_at.is_(None))
            .order_by(FleetOutbox.id)
            .limit(limit)
        )
        return [Outgoing(r.id, r.topic, r.payload.encode()) for r in rows]


def mark_seen(*, sessions: sessionmaker[Session], topic: str, header_id: int) -> None:
    """The broker delivered the message back to the bridge's echo session: it was published."""
    with transaction(sessions) as session:
        session.execute(
            update(FleetOutbox)
            .where(
                FleetOutbox.topic == topic,
                FleetOutbox.header_id == header_id,
                FleetOutbox.published_at.is_(None),
            )
            .values(published_at=utcnow())
        )


def mark_published(*, sessions: sessionmaker[Session], ids: Sequence[int]) -> None:
    if not ids:
        return
    with transaction(sessions) as session:
        session.execute(
            update(FleetOutbox).where(FleetOutbox.id.in_(ids)).values(published_at=utcnow())
        )
