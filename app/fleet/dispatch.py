"""Orders from the plan (docs/fleet.md#task-to-order): what each robot on the fleet is sent next.

`dispatch` reads the head of every lineage on a fleet site and brings the orders in line
with it, in one transaction that writes the order rows and their messages to the outbox:

- a robot on the fleet (it said ONLINE) with no open order gets one: its next decided task
  (by planned start on a timed run, else by queue order) that is not reported done or
  failed; a team task sends one order per member;
- an open order whose task moved in time gets an update (orderUpdateId + 1);
- an open order whose task a revision took from the robot (or dropped) is cancelled with a
  `cancelOrder` instant action.

Called again with nothing new it writes nothing: every order is a row keyed by (lineage
root, task, robot), and its orderId is made of the same three.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

from sqlalchemy import Select, select
from sqlalchemy.orm import Session, sessionmaker

from app.domain.lifecycle import RunStatus
from app.fleet import outbox
from app.fleet.states import OrderState
from app.fleet.vda5050 import (
    CANCEL_ORDER,
    ORDER_ID,
    PLANNED_DURATION_S,
    PLANNED_END,
    PLANNED_START,
    PROTOCOL_VERSION,
    RUN_ID,
    TASK_ID,
    Action,
    ActionParameter,
    BlockingType,
    ConnectionState,
    InstantActions,
    Node,
    Order,
    Topic,
    topic,
)
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import transaction
from app.store.fleet_models import FleetOrder, FleetRobot
from app.store.models import Decision, Run, utcnow

# Lineages whose head may still have work for a robot; a blocked or failed run is left as is.
DISPATCHED = (
    RunStatus.QUEUED,
    RunStatus.RUNNING,
    RunStatus.INTERRUPTED,
    RunStatus.AWAITING_REVIEW,
    RunStatus.COMPLETED,
)
FINAL_REPORTS = frozenset({"done", "failed"})
NO_ZONE = "site"  # the node of a task without a zone


@dataclass(frozen=True)
class FleetNames:
    """How the bridge addresses robots, and which runs it sends: the sites' (None: every
    site) whose head was made `since` the store's fleet began (None: every one;
    docs/fleet.md#task-to-order)."""

    interface: str
    manufacturer: str
    sites: frozenset[str] | None = None
    since: datetime | None = None

    @classmethod
    def parse_sites(cls, text: str) -> frozenset[str] | None:
        names = frozenset(s.strip() for s in text.split(",") if s.strip())
        return None if "*" in names else names


@dataclass(frozen=True)
class Planned:
    """One robot's part of one decided task, as the head plans it."""

    task_index: int
    task_id: str
    robot: str
    start: float | None
    end: float | None

    @property
    def key(self) -> tuple[str, str]:
        return self.task_id, self.robot


def order_id(lineage: str, task_id: str, robot: str) -> str:
    return f"{lineage}:{task_id}:{robot}"


def lineage_root(session: Session, run: Run) -> str:
    seen = {run.id}
    current = run
    while current.revision_of is not None and current.revision_of not in seen:
        parent = repo.get_run(session=session, run_id=current.revision_of)
        if parent is None:
            break
        seen.add(parent.id)
        current = parent
    return current.id


def dispatch(
    *,
    sessions: sessionmaker[Session],
    names: FleetNames,
    fence: Callable[[Session], bool] | None = None,
) -> int:
    """Bring the orders in line with the plans; the number of messages written. `fence`: a
    check in the same transaction that this process is still the active bridge
    (app.fleet.lease); when it fails, nothing is written."""
    with transaction(sessions) as session:
        if fence is not None and not fence(session):
            return 0
        online = {
            r.serial_number
            for r in session.scalars(
                select(FleetRobot).where(
                    FleetRobot.manufacturer == names.manufacturer,
                    FleetRobot.connection == ConnectionState.ONLINE,
                    FleetRobot.fatal.is_(None),
                )
            )
        }
        busy = {
            o.serial_number
            for o in session.scalars(
                select(FleetOrder).where(
                    FleetOrder.manufacturer == names.manufacturer,
                    FleetOrder.state == OrderState.SENT,
                )
            )
        }
        written = 0
        for head in _heads(session, names):
            written += _dispatch_head(session, names, head, online, busy)
        return written


def _heads(session: Session, names: FleetNames) -> list[Run]:
    query = select(Run).where(Run.superseded_by.is_(None), Run.status.in_(DISPATCHED))
    return list(session.scalars(on_the_fleet(query, names).order_by(Run.created_at, Run.id)))


def on_the_fleet(query: Select[Run], names: FleetNames) -> Select[Run]:
    """The heads among `query`'s runs whose plans go to the robots: on a fleet site, and made
    since the store's fleet began (a plan made before goes out once it is revised)."""
    if names.sites is not None:
        query = query.where(Run.site.in_(sorted(names.sites)))
    if names.since is not None:
        query = query.where(Run.created_at >= names.since)
    return query


def _dispatch_head(
    session: Session, names: FleetNames, head: Run, online: set[str], busy: set[str]
) -> int:
    root = lineage_root(session, head)
    reports = {r.task_id: r.state for r in repo.execution_reports(session=session, run_id=head.id)}
    planned = [p for p in _planned(decision_repo.decisions(session=session, run_id=head.id))]
    orders = {
        (o.task_id, o.robot): o
        for o in session.scalars(select(FleetOrder).where(FleetOrder.lineage == root))
    }
    if not planned and not orders:
        return 0
    tasks = {str(t["id"]): t for t in head.request["instance_data"]["tasks"]}
    origin = _origin(head)
    wanted = {p.key: p for p in planned}
    decided = {p.task_id for p in planned}
    settled = head.status == RunStatus.COMPLETED
    written = 0
    for key, order in orders.items():
        if order.state != OrderState.SENT:
            continue
        p = wanted.get(key)
        if p is None or reports.get(order.task_id) in FINAL_REPORTS:
            # Taken from the robot: the head decided it for others, or finished without it. A
            # head still deciding may yet give it back to the same robot: the order waits.
            if p is None and (order.task_id in decided or settled):
                _cancel(session, names, order)
                busy.discard(order.serial_number)
                written += 1
            continue
        if (p.start, p.end) != (order.planned_start, order.planned_end):
            order.update_id += 1
            order.planned_start, order.planned_end = p.start, p.end
            order.run_id = head.id
            _send(session, names, order, tasks[order.task_id], origin)
            written += 1
    for p in planned:
        if p.robot not in online or p.robot in busy:
            continue
        if reports.get(p.task_id) in FINAL_REPORTS:
            continue
        earlier = orders.get(p.key)
        if earlier is not None:
            if earlier.state not in (OrderState.CANCELLED, OrderState.FAILED):
                continue  # sent, or the robot finished its part
            # Cancelled, or failed and planned again by a revision (a failed task is never
            # pinned): the same order again, as an update.
            earlier.state = OrderState.SENT
            earlier.action_status = None
            earlier.update_id += 1
            earlier.run_id = head.id
            earlier.planned_start, earlier.planned_end = p.start, p.end
            busy.add(p.robot)
            _send(session, names, earlier, tasks[p.task_id], origin)
            written += 1
            continue
        order = FleetOrder(
            order_id=order_id(root, p.task_id, p.robot),
            lineage=root,
            run_id=head.id,
            task_index=p.task_index,
            task_id=p.task_id,
            robot=p.robot,
            manufacturer=names.manufacturer,
            serial_number=p.robot,
            update_id=0,
            planned_start=p.start,
            planned_end=p.end,
            state=OrderState.SENT,
        )
        session.add(order)
        orders[p.key] = order
        busy.add(p.robot)
        _send(session, names, order, tasks[p.task_id], origin)
        written += 1
    return written


def _planned(decisions: Iterable[Decision]) -> list[Planned]:
    """Each robot's part of each decision, in the order the robot is to do them."""
    out: list[Planned] = []
    for d in decisions:
        members = [str(m["robot"]) for m in d.team] if d.team else [d.robot_name]
        for robot in dict.fromkeys(members):
            out.append(Planned(d.task_index, d.task_id, robot, d.start, d.end))
    # A timed plan by start (then queue order); an untimed one in queue order.
    return sorted(out, key=lambda p: (p.start if p.start is not None else 0.0, p.task_index))


def _origin(run: Run) -> datetime | None:
    text = run.request["instance_data"].get("start")
    if not text:
        return None
    at = datetime.fromisoformat(str(text))
    return at if at.tzinfo is not None else at.replace(tzinfo=UTC)


def _addressed(
    session: Session, names: FleetNames, order: FleetOrder, kind: Topic
) -> tuple[str, dict[str, Any]]:
    """The topic of a message to the order's robot, and the header fields it starts with."""
    name = topic(names.interface, names.manufacturer, order.serial_number, kind)
    return name, {
        "header_id": outbox.next_header_id(session, name),
        "timestamp": utcnow(),
        "version": PROTOCOL_VERSION,
        "manufacturer": names.manufacturer,
        "serial_number": order.serial_number,
    }


def _send(
    session: Session,
    names: FleetNames,
    order: FleetOrder,
    task: Mapping[str, Any],
    origin: datetime | None,
) -> None:
    name, header = _addressed(session, names, order, Topic.ORDER)
    message = Order(
        **header,
        order_id=order.order_id,
        order_update_id=order.update_id,
        nodes=[
            Node(
                node_id=str(task.get("zone") or NO_ZONE),
                sequence_id=0,
                released=True,
                actions=[_action(order, task, origin)],
            )
        ],
    )
    outbox.enqueue(session, name, message)


def _action(order: FleetOrder, task: Mapping[str, Any], origin: datetime | None) -> Action:
    params: list[ActionParameter] = [
        ActionParameter(key=TASK_ID, value=order.task_id),
        ActionParameter(key=RUN_ID, value=order.run_id),
    ]
    if order.planned_start is not None and order.planned_end is not None:
        if origin is not None:
            for key, minute in (
                (PLANNED_START, order.planned_start),
                (PLANNED_END, order.planned_end),
            ):
                at = origin + timedelta(minutes=minute)
                params.append(ActionParameter(key=key, value=at.isoformat()))
        seconds = (order.planned_end - order.planned_start) * 60.0
        params.append(ActionParameter(key=PLANNED_DURATION_S, value=round(seconds, 3)))
    features: Sequence[str] = task.get("features") or ()
    kind = task.get("type") if task.get("type") not in (None, "Custom") else None
    return Action(
        action_type=str(kind or (features[0] if features else "work")),
        action_id=order.task_id,
        blocking_type=BlockingType.HARD,
        action_description=str(task.get("name") or order.task_id)[:200],
        action_parameters=params,
    )


def _cancel(session: Session, names: FleetNames, order: FleetOrder) -> None:
    order.state = OrderState.CANCELLED
    name, header = _addressed(session, names, order, Topic.INSTANT_ACTIONS)
    message = InstantActions(
        **header,
        actions=[
            Action(
                action_type=CANCEL_ORDER,
                action_id=f"cancel:{order.order_id}:{order.update_id}",
                blocking_type=BlockingType.HARD,
                action_parameters=[ActionParameter(key=ORDER_ID, value=order.order_id)],
            )
        ],
    )
    outbox.enqueue(session, name, message)
