"""Robot state in (docs/fleet.md#state-to-report): a VDA 5050 message becomes execution reports
or a revision, through the same code the HTTP API uses.

- an action RUNNING is the task `started`, FINISHED `done`, FAILED `failed`, at the message's
  timestamp, sent to the head of the order's lineage with app.plans.reports.report (a team
  task: started at its first member's RUNNING, done when every member FINISHED, failed at the
  first FAILED);
- `connection` OFFLINE or CONNECTIONBROKEN, or an error of level FATAL, makes the robot
  unavailable: app.plans.revisions.create_revision on every head that still has unfinished
  work for it, once (the revision takes the robot's tasks away, so a repeat finds none);
- the battery is kept on the robot's row.

A message that is not VDA 5050, names a robot that never said ONLINE or an order the bridge
never sent it, repeats a headerId or goes back in time is refused: counted and logged, never
stored. A message that changes nothing costs no write: the newest headerId and timestamp per
robot and topic are kept in memory (read from the robot's row on first use) and written with
the next change.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime

from pydantic import ValidationError
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.domain.errors import DomainError
from app.fleet.dispatch import FleetNames
from app.fleet.metrics import FleetMetrics
from app.fleet.outage import revise_without
from app.fleet.states import OrderState, Refusal
from app.fleet.vda5050 import (
    ActionStatus,
    Connection,
    ConnectionState,
    Message,
    State,
    Topic,
    parse_topic,
)
from app.plans.reports import ExecutionState, Update, head_of, report
from app.runs.worker import RunWorker
from app.store import repository as repo
from app.store.db import transaction
from app.store.fleet_models import FleetOrder, FleetRobot
from app.store.models import as_utc

log = logging.getLogger("ltaa.fleet")

REPORTED_AS = {
    ActionStatus.RUNNING: ExecutionState.STARTED,
    ActionStatus.FINISHED: ExecutionState.DONE,
    ActionStatus.FAILED: ExecutionState.FAILED,
}
ORDER_STATE_OF = {
    ActionStatus.FINISHED: OrderState.FINISHED,
    ActionStatus.FAILED: OrderState.FAILED,
}
UNAVAILABLE = frozenset({ConnectionState.OFFLINE, ConnectionState.CONNECTIONBROKEN})
BATTERY_STEP = 1.0  # percent: a smaller change is not worth a write


@dataclass
class Seen:
    header_id: int | None
    at: datetime | None


@dataclass
class Snapshot:
    """What a robot's row says of its battery and FATAL error."""

    battery_charge: float | None
    charging: bool | None
    fatal: str | None

    @classmethod
    def of(cls, row: FleetRobot) -> Snapshot:
        return cls(row.battery_charge, row.charging, row.fatal)


class Intake:
    """Takes each message the bridge receives; `receive` is called from one thread at a time."""

    def __init__(
        self,
        *,
        sessions: sessionmaker[Session],
        worker: RunWorker,
        settings: Settings,
        names: FleetNames,
        metrics: FleetMetrics,
        on_change: Callable[[], None] | None = None,
    ) -> None:
        self.sessions = sessions
        self.worker = worker
        self.settings = settings
        self.names = names
        self.metrics = metrics
        self.on_change = on_change
        self._seen: dict[tuple[str, str, Topic], Seen] = {}
        # Each robot's orders and row as last read or written here: a heartbeat that changes
        # nothing is answered from memory (docs/fleet.md#refused-messages). Dispatch writes
        # orders in another transaction: the bridge calls `orders_changed` after it.
        self._orders: dict[tuple[str, str], dict[str, FleetOrder]] = {}
        self._rows: dict[tuple[str, str], Snapshot] = {}
        self._dirty = False

    def orders_changed(self) -> None:
        self._orders.clear()

    def take_changed(self) -> bool:
        """Whether a message since the last call changed something (then dispatch)."""
        dirty, self._dirty = self._dirty, False
        return dirty

    def receive(self, topic: str, payload: bytes, *, retained: bool = False) -> Refusal | None:
        """Apply one message; the reason it was refused, or None."""
        where = parse_topic(self.names.interface, topic)
        if where is None:
            return self._refuse(Refusal.FOREIGN_TOPIC, topic, "not a robot's state or connection")
        manufacturer, serial, kind = where
        self.metrics.received(kind)
        message: Message
        try:
            if kind == Topic.STATE:
                message = State.model_validate_json(payload)
            elif kind == Topic.CONNECTION:
                message = Connection.model_validate_json(payload)
            else:  # our own orders and instant actions, echoed by a broker: not for us
                return self._refuse(Refusal.FOREIGN_TOPIC, topic, "the bridge reads state only")
        except ValidationError as exc:
            first = exc.errors()[0]
            where_in = ".".join(str(p) for p in first["loc"]) or "(message)"
            return self._refuse(Refusal.MALFORMED, topic, f"{where_in}: {first['msg']}")
        if (message.manufacturer, message.serial_number) != (manufacturer, serial):
            return self._refuse(
                Refusal.MALFORMED,
                topic,
                f"the header names {message.manufacturer}/{message.serial_number}",
            )
        seen = self._last(manufacturer, serial, kind)
        if seen is None and kind == Topic.STATE:
            return self._refuse(Refusal.UNKNOWN_ROBOT, topic, "it never said ONLINE")
        # A last will is written when the robot connects, before the ONLINE it follows: its
        # timestamp (and, for some vehicles, its headerId) is older. An outage is never
        # refused for that; a repeat of one is a no-op below.
        will = (
            isinstance(message, Connection)
            and message.connection_state == ConnectionState.CONNECTIONBROKEN
        )
        if seen is not None and seen.header_id is not None and not will:
            if message.header_id <= seen.header_id:
                if retained and message.header_id == seen.header_id:
                    return None  # the broker's retained copy of what we already have
                return self._refuse(
                    Refusal.REPLAYED,
                    topic,
                    f"headerId {message.header_id} after {seen.header_id}",
                )
            if seen.at is not None and message.timestamp < seen.at:
                return self._refuse(
                    Refusal.OUT_OF_ORDER,
                    topic,
                    f"timestamp {message.timestamp.isoformat()} before {seen.at.isoformat()}",
                )
        if isinstance(message, State):
            return self._state(topic, message)
        assert isinstance(message, Connection)
        return self._connection(message)

    # -- bookkeeping -----------------------------------------------------------------

    def _refuse(self, why: Refusal, topic: str, detail: str) -> Refusal:
        self.metrics.refused(why)
        log.warning("fleet message refused (%s) on %s: %s", why.value, topic, detail)
        return why

    def _last(self, manufacturer: str, serial: str, kind: Topic) -> Seen | None:
        key = (manufacturer, serial, kind)
        if key in self._seen:
            return self._seen[key]
        with self.sessions() as session:
            row = session.get(FleetRobot, (manufacturer, serial))
        if row is None:
            return None
        self._rows[(manufacturer, serial)] = Snapshot.of(row)
        if kind == Topic.STATE:
            seen = Seen(row.state_header_id, _aware(row.state_at))
        else:
            seen = Seen(row.connection_header_id, _aware(row.connection_at))
        self._seen[key] = seen
        return seen

    def _accept(self, row: FleetRobot, kind: Topic, message: Message) -> None:
        """The newest header on the row (written with the change) and in memory."""
        seen = self._seen.get((message.manufacturer, message.serial_number, kind))
        if seen is not None and seen.header_id is not None and seen.header_id > message.header_id:
            return  # a will older than what it follows: the newest header stays
        if kind == Topic.STATE:
            row.state_header_id, row.state_at = message.header_id, message.timestamp
        else:
            row.connection_header_id, row.connection_at = message.header_id, message.timestamp
        self._seen[(message.manufacturer, message.serial_number, kind)] = Seen(
            message.header_id, message.timestamp
        )

    def _remember(self, message: Message, kind: Topic) -> None:
        """A message that changed nothing: its header is kept in memory only."""
        self._seen[(message.manufacturer, message.serial_number, kind)] = Seen(
            message.header_id, message.timestamp
        )

    # -- connection ------------------------------------------------------------------

    def _connection(self, message: Connection) -> Refusal | None:
        key = (message.manufacturer, message.serial_number)
        with transaction(self.sessions) as session:
            row = session.get(FleetRobot, key)
            if row is None:
                row = FleetRobot(
                    manufacturer=message.manufacturer,
                    serial_number=message.serial_number,
                    connection=message.connection_state.value,
                )
                session.add(row)
            before = row.connection
            row.connection = message.connection_state.value
            if message.connection_state == ConnectionState.ONLINE:
                row.fatal = None
            self._accept(row, Topic.CONNECTION, message)
            self._rows[key] = Snapshot.of(row)
        log.info(
            "fleet robot %s/%s is %s",
            message.manufacturer,
            message.serial_number,
            message.connection_state.value,
        )
        if message.connection_state in UNAVAILABLE and before != message.connection_state:
            self._unavailable(message.serial_number, f"connection {message.connection_state}")
        self._changed()
        return None

    # -- state -----------------------------------------------------------------------

    def _robot_orders(self, manufacturer: str, serial: str) -> dict[str, FleetOrder]:
        key = (manufacturer, serial)
        orders = self._orders.get(key)
        if orders is None:
            with self.sessions() as session:
                rows = session.scalars(
                    select(FleetOrder).where(
                        FleetOrder.manufacturer == manufacturer,
                        FleetOrder.serial_number == serial,
                    )
                )
                orders = self._orders[key] = {o.order_id: o for o in rows}
                session.expunge_all()
        # The orders read here, not the memo again: `orders_changed` may clear it meanwhile.
        return orders

    def _state(self, topic: str, message: State) -> Refusal | None:
        by_id = self._robot_orders(message.manufacturer, message.serial_number)
        if message.order_id and message.order_id not in by_id:
            return self._refuse(
                Refusal.UNKNOWN_ORDER, topic, f"orderId '{message.order_id}' was never sent"
            )
        current = by_id.get(message.order_id)
        moves = []
        if current is not None and current.state == OrderState.SENT:
            moves = [
                a.action_status
                for a in message.action_states
                if a.action_id == current.task_id
                and a.action_status in REPORTED_AS
                and a.action_status != current.action_status
            ]
        refused = None
        for status in moves:
            assert current is not None  # moves come from the current order only
            refused = self._move(current, status, message.timestamp) or refused
        fatal = message.fatal()
        changed = self._robot_row(message, fatal[0].error_type if fatal else None, bool(moves))
        if fatal and changed == "fatal":
            self._unavailable(message.serial_number, f"FATAL error {fatal[0].error_type}")
        if moves or changed:
            self._changed()
        return refused

    def _robot_row(self, message: State, fatal: str | None, moved: bool) -> str | None:
        """Battery, FATAL error and the header on the robot's row when one of them changed
        (or an action moved); 'fatal' when a FATAL error is new."""
        key = (message.manufacturer, message.serial_number)
        known = self._rows.get(key)
        battery = message.battery_state
        if (
            known is not None
            and not moved
            and (fatal is None) == (known.fatal is None)
            and known.battery_charge is not None
            and abs(known.battery_charge - battery.battery_charge) < BATTERY_STEP
            and known.charging == battery.charging
        ):
            self._remember(message, Topic.STATE)
            return None
        with transaction(self.sessions) as session:
            row = session.get(FleetRobot, (message.manufacturer, message.serial_number))
            if row is None:
                return None
            new_fatal = fatal is not None and row.fatal is None
            changed = (
                moved
                or new_fatal
                or (fatal is None and row.fatal is not None)
                or row.battery_charge is None
                or abs(row.battery_charge - battery.battery_charge) >= BATTERY_STEP
                or row.charging != battery.charging
            )
            if not changed:
                self._remember(message, Topic.STATE)
                return None
            row.battery_charge = battery.battery_charge
            row.charging = battery.charging
            row.fatal = fatal
            self._accept(row, Topic.STATE, message)
            self._rows[key] = Snapshot.of(row)
        return "fatal" if new_fatal else "row"

    def _move(self, order: FleetOrder, status: ActionStatus, at: datetime) -> Refusal | None:
        """One action's new status: the report it implies on the lineage's head, then the
        order's row (a crash between the two: the robot's next state says it again, and the
        report, idempotent, is a no-op)."""
        with self.sessions() as session:
            run = repo.get_run(session=session, run_id=order.lineage)
            head = head_of(session, run) if run is not None else None
            team = self._team_states(session, order)
        if head is None:
            return Refusal.UNKNOWN_ORDER
        target = _team_report(status, team, order.robot) if team else REPORTED_AS[status]
        if target is not None:
            try:
                report(
                    sessions=self.sessions,
                    run_id=head,
                    updates=[Update(order.task_id, target, at)],
                )
            except DomainError as exc:
                # The order stays as it was: the robot repeats its state every interval, and
                # the report lands once the head can take it (a revision still deciding the
                # task), or dispatch cancels the order (a revision took the task away).
                return self._refuse(
                    Refusal.REPORT_REFUSED,
                    f"{order.serial_number}/{order.task_id}",
                    f"{exc.field}: {exc}",
                )
        with transaction(self.sessions) as session:
            row = session.get(FleetOrder, order.id)
            if row is not None:
                row.action_status = status.value
                if status in ORDER_STATE_OF:
                    row.state = ORDER_STATE_OF[status]
        order.action_status = status.value
        if status in ORDER_STATE_OF:
            order.state = ORDER_STATE_OF[status]
        return None

    def _team_states(self, session: Session, order: FleetOrder) -> dict[str, str | None]:
        """The other members' last action status on this task, by robot; {} for one robot."""
        rows = session.scalars(
            select(FleetOrder).where(
                FleetOrder.lineage == order.lineage, FleetOrder.task_id == order.task_id
            )
        )
        states = {r.robot: r.action_status for r in rows if r.state != OrderState.CANCELLED}
        return states if len(states) > 1 else {}

    def _unavailable(self, robot: str, why: str) -> None:
        revise_without(
            sessions=self.sessions,
            worker=self.worker,
            settings=self.settings,
            names=self.names,
            robot=robot,
            why=why,
        )

    def _changed(self) -> None:
        self._dirty = True
        if self.on_change is not None:
            self.on_change()


def _team_report(
    status: ActionStatus, team: dict[str, str | None], robot: str
) -> ExecutionState | None:
    """A team task's report when one member's action moves (docs/fleet.md#teams)."""
    if status == ActionStatus.RUNNING:
        return ExecutionState.STARTED
    if status == ActionStatus.FAILED:
        return ExecutionState.FAILED
    others = [s for r, s in team.items() if r != robot]
    if all(s == ActionStatus.FINISHED for s in others):
        return ExecutionState.DONE
    return None


def _aware(at: datetime | None) -> datetime | None:
    return None if at is None else as_utc(at)
