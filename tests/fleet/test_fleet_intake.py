"""The bridge's logic in process (docs/fleet.md): orders from a completed run's plan, robot
state back as execution reports, a robot gone as a revision, and every kind of bad message
refused and counted with nothing stored. The broker is exercised in test_fleet_e2e.py."""

from __future__ import annotations

import copy
import json
from collections.abc import Iterator
from dataclasses import replace
from datetime import UTC, datetime, timedelta
from typing import Any

import pytest
from fastapi.testclient import TestClient
from prometheus_client import CollectorRegistry
from sqlalchemy import event, func, select

from app.fleet import outbox
from app.fleet.dispatch import FleetNames, dispatch
from app.fleet.intake import Intake
from app.fleet.lease import LocalLease
from app.fleet.metrics import FleetMetrics
from app.fleet.states import Refusal
from app.fleet.vda5050 import (
    PROTOCOL_VERSION,
    ActionState,
    ActionStatus,
    BatteryState,
    Connection,
    ConnectionState,
    ErrorLevel,
    Order,
    RobotError,
    SafetyState,
    State,
    Topic,
    topic,
)
from app.store.fleet_models import FleetOrder, FleetRobot
from app.store.models import ExecutionReport, utcnow
from tests.plans.test_revisions import BASELINE, HEAVY_DOWN, completed_run, revise, wait_status
from tests.plans.test_timed_team_revisions import BODY as TEAM_BODY
from tests.plans.test_timed_team_revisions import completed
from tests.support.vda5050_schemas import validate

MAKER = "acme"


class Fleet:
    """An Intake on a test client's store, with a clock and headerIds of its own per robot."""

    def __init__(self, client: TestClient) -> None:
        runs = client.app.state.runs  # type: ignore[attr-defined]
        self.sessions = runs.sessions
        self.names = FleetNames(interface="uagv", manufacturer=MAKER, sites=None)
        self.metrics = FleetMetrics(CollectorRegistry())
        self.intake = Intake(
            sessions=runs.sessions,
            worker=runs.worker,
            settings=client.app.state.settings,  # type: ignore[attr-defined]
            names=self.names,
            metrics=self.metrics,
        )
        self.headers: dict[tuple[str, Topic], int] = {}
        self.clock = datetime(2026, 12, 5, 8, 0, tzinfo=UTC)

    def _header(self, robot: str, kind: Topic) -> tuple[int, datetime]:
        self.headers[(robot, kind)] = self.headers.get((robot, kind), -1) + 1
        self.clock += timedelta(seconds=1)
        return self.headers[(robot, kind)], self.clock

    def connection(self, robot: str, state: ConnectionState) -> Refusal | None:
        header, at = self._header(robot, Topic.CONNECTION)
        message = Connection(
            header_id=header,
            timestamp=at,
            version=PROTOCOL_VERSION,
            manufacturer=MAKER,
            serial_number=robot,
            connection_state=state,
        )
        return self.send(robot, Topic.CONNECTION, message.wire())

    def state(
        self,
        robot: str,
        order: Order | None,
        status: ActionStatus | None = None,
        *,
        battery: float = 90.0,
        fatal: bool = False,
    ) -> Refusal | None:
        header, at = self._header(robot, Topic.STATE)
        actions = (
            [ActionState(action_id=order.task_actions()[0].action_id, action_status=status)]
            if order is not None and status is not None
            else []
        )
        message = State(
            header_id=header,
            timestamp=at,
            version=PROTOCOL_VERSION,
            manufacturer=MAKER,
            serial_number=robot,
            order_id=order.order_id if order else "",
            order_update_id=order.order_update_id if order else 0,
            last_node_id="",
            last_node_sequence_id=0,
            node_states=[],
            edge_states=[],
            driving=False,
            action_states=actions,
            battery_state=BatteryState(battery_charge=battery, charging=False),
            operating_mode="AUTOMATIC",
            errors=[RobotError(error_type="motor", error_level=ErrorLevel.FATAL)] if fatal else [],
            safety_state=SafetyState(),
        )
        return self.send(robot, Topic.STATE, message.wire())

    def send(self, robot: str, kind: Topic, payload: bytes, **kw: Any) -> Refusal | None:
        return self.intake.receive(topic("uagv", MAKER, robot, kind), payload, **kw)

    def dispatch(self) -> list[tuple[str, dict[str, Any]]]:
        """Dispatch and take what it wrote from the outbox, each checked against the schema."""
        if dispatch(sessions=self.sessions, names=self.names):
            self.intake.orders_changed()  # as the bridge does
        sent = outbox.pending(sessions=self.sessions)
        outbox.mark_published(sessions=self.sessions, ids=[m.id for m in sent])
        out = []
        for m in sent:
            body = json.loads(m.payload)
            validate(m.topic.rsplit("/", 1)[-1], body)
            out.append((m.topic, body))
        return out

    def reports(self, run_id: str) -> dict[str, str]:
        with self.sessions() as session:
            rows = session.scalars(select(ExecutionReport).where(ExecutionReport.run_id == run_id))
            return {r.task_id: r.state for r in rows}

    def rows(self) -> tuple[int, int, int]:
        with self.sessions() as session:
            return (
                session.scalar(select(func.count()).select_from(ExecutionReport)) or 0,
                session.scalar(select(func.count()).select_from(FleetRobot)) or 0,
                session.scalar(select(func.count()).select_from(FleetOrder)) or 0,
            )


@pytest.fixture
def fleet(client: TestClient) -> Iterator[tuple[TestClient, Fleet, str, list[str]]]:
    run_id = completed_run(client, BASELINE)
    state = client.get(f"/runs/{run_id}").json()
    robots = sorted({a["robot"] for a in state["assignments"]})
    yield client, Fleet(client), run_id, robots


def _orders(sent: list[tuple[str, dict[str, Any]]]) -> dict[str, Order]:
    return {
        body["serialNumber"]: Order.model_validate(body)
        for name, body in sent
        if name.endswith("/order")
    }


def test_one_order_per_online_robot_then_the_next_as_each_finishes(
    fleet: tuple[TestClient, Fleet, str, list[str]],
) -> None:
    client, f, run_id, robots = fleet
    assert f.dispatch() == []  # nobody online: nothing sent
    for robot in robots:
        assert f.connection(robot, ConnectionState.ONLINE) is None
    orders = _orders(f.dispatch())
    assert sorted(orders) == robots
    assert f.dispatch() == []  # again: nothing new
    robot = robots[0]
    first = orders[robot]
    action = first.task_actions()[0]
    assert first.order_id == f"{run_id}:{action.action_id}:{robot}" and first.order_update_id == 0
    assert action.parameter("taskId") == action.action_id and action.parameter("runId") == run_id
    assert f.state(robot, first, ActionStatus.RUNNING) is None
    assert f.reports(run_id) == {action.action_id: "started"}
    assert f.dispatch() == []  # still busy
    assert f.state(robot, first, ActionStatus.FINISHED) is None
    assert f.reports(run_id) == {action.action_id: "done"}
    following = _orders(f.dispatch())
    assert list(following) == [robot]
    assert following[robot].task_actions()[0].action_id != action.action_id
    # The same state again changes nothing (idempotent per order, action and status).
    before = f.rows()
    assert f.state(robot, first, ActionStatus.FINISHED) is None
    assert f.rows() == before
    # The site's estimates learned from the robot's report.
    estimates = client.get("/sites/default/estimates").json()
    assert sum(r["successes"] for e in estimates["robots"] for r in e["features"]) >= 1


def test_a_failed_action_is_a_failed_task(fleet: tuple[TestClient, Fleet, str, list[str]]) -> None:
    _, f, run_id, robots = fleet
    f.connection(robots[0], ConnectionState.ONLINE)
    order = _orders(f.dispatch())[robots[0]]
    assert f.state(robots[0], order, ActionStatus.FAILED) is None
    assert f.reports(run_id) == {order.task_actions()[0].action_id: "failed"}


def test_bad_messages_are_refused_counted_and_store_nothing(
    fleet: tuple[TestClient, Fleet, str, list[str]],
) -> None:
    _, f, run_id, robots = fleet
    robot = robots[0]
    f.connection(robot, ConnectionState.ONLINE)
    order = _orders(f.dispatch())[robot]
    before = f.rows()
    state_topic = Topic.STATE
    # Not JSON; JSON but not VDA 5050; a header naming another robot.
    assert f.send(robot, state_topic, b"\x00not json") == Refusal.MALFORMED
    assert f.send(robot, state_topic, b'{"headerId": 1}') == Refusal.MALFORMED
    # A robot that never said ONLINE.
    assert f.state("ghost", None) == Refusal.UNKNOWN_ROBOT
    # An order the bridge never sent.
    fake = order.model_copy(update={"order_id": "not-ours"})
    assert f.state(robot, fake, ActionStatus.RUNNING) == Refusal.UNKNOWN_ORDER
    assert f.rows() == before and f.reports(run_id) == {}
    # Accepted, then replayed (the same headerId), then from the past (a newer headerId with
    # an older timestamp).
    assert f.state(robot, order, ActionStatus.RUNNING) is None
    after = f.rows()
    f.headers[(robot, Topic.STATE)] -= 1
    assert f.state(robot, order, ActionStatus.FINISHED) == Refusal.REPLAYED
    f.clock -= timedelta(hours=1)
    assert f.state(robot, order, ActionStatus.FINISHED) == Refusal.OUT_OF_ORDER
    assert f.rows() == after
    assert f.reports(run_id) == {order.task_actions()[0].action_id: "started"}
    for why in (
        Refusal.MALFORMED,
        Refusal.UNKNOWN_ROBOT,
        Refusal.UNKNOWN_ORDER,
        Refusal.REPLAYED,
        Refusal.OUT_OF_ORDER,
    ):
        assert f.metrics.refused_count(why) >= 1, why
    assert f.metrics.refused_count(Refusal.MALFORMED) == 2
    # And the intake still works.
    f.clock += timedelta(hours=2)
    assert f.state(robot, order, ActionStatus.FINISHED) is None


def test_a_robot_gone_revises_its_tasks_to_the_others_and_cancels_its_order(
    fleet: tuple[TestClient, Fleet, str, list[str]],
) -> None:
    client, f, run_id, robots = fleet
    for robot in robots:
        f.connection(robot, ConnectionState.ONLINE)
    orders = _orders(f.dispatch())
    gone = robots[1]
    assert f.connection(gone, ConnectionState.CONNECTIONBROKEN) is None
    head = wait_status(client, run_id, "completed")["superseded_by"]
    assert head is not None
    revised = wait_status(client, head, "completed")
    assert gone not in {a["robot"] for a in revised["assignments"] if not a.get("pinned")}
    sent = f.dispatch()
    cancels = [b for name, b in sent if name.endswith("/instantActions")]
    # The robot gone loses its order; another robot's order not yet started may move too
    # (pin "reported" keeps only what the site reported), and is then cancelled as well.
    cancelled = {c["serialNumber"]: c["actions"][0]["actionParameters"] for c in cancels}
    assert cancelled[gone] == [{"key": "orderId", "value": orders[gone].order_id}]
    now = {(str(a["task_id"]), a["robot"]) for a in revised["assignments"]}
    for robot in cancelled:
        task = orders[robot].task_actions()[0].action_id
        assert (task, robot) not in now
    # Again: the robot has no work left in the head, so no second revision.
    assert f.connection(gone, ConnectionState.ONLINE) is None
    assert f.connection(gone, ConnectionState.OFFLINE) is None
    assert client.get(f"/runs/{head}").json()["superseded_by"] is None


def test_a_fatal_error_makes_the_robot_unavailable(
    fleet: tuple[TestClient, Fleet, str, list[str]],
) -> None:
    client, f, run_id, robots = fleet
    f.connection(robots[0], ConnectionState.ONLINE)
    order = _orders(f.dispatch())[robots[0]]
    assert f.state(robots[0], order, ActionStatus.RUNNING, fatal=True) is None
    assert wait_status(client, run_id, "completed")["superseded_by"] is not None
    listed = client.get("/fleet/robots").json()
    (row,) = [r for r in listed["robots"] if r["serial_number"] == robots[0]]
    assert row["fatal"] == "motor" and row["battery_charge"] == 90.0


def test_the_console_shows_each_robots_battery(
    fleet: tuple[TestClient, Fleet, str, list[str]],
) -> None:
    client, f, _, robots = fleet
    page = client.get("/console/fleet")
    assert page.status_code == 200 and "bridge is off" in page.text
    f.connection(robots[0], ConnectionState.ONLINE)
    f.state(robots[0], None, battery=57.0)
    page = client.get("/console/fleet")
    assert robots[0] in page.text and "57%" in page.text


def test_a_team_task_is_one_order_per_member_done_when_every_member_finished(
    client: TestClient,
) -> None:
    """docs/fleet.md#teams, on the timed team scenario: the first task is a two-robot lift."""
    body = copy.deepcopy(TEAM_BODY)
    body["tasks"] = body["tasks"][:1]  # the beam: {"heavy": 2}, 30 minutes
    run = completed(client, body)
    (beam,) = run["assignments"]
    members = [m["robot"] for m in beam["team"]]
    f = Fleet(client)
    for robot in members:
        f.connection(robot, ConnectionState.ONLINE)
    orders = _orders(f.dispatch())
    assert sorted(orders) == sorted(members)
    for order in orders.values():
        action = order.task_actions()[0]
        assert action.parameter("plannedDurationS") == 30 * 60.0
        start = datetime.fromisoformat(str(action.parameter("plannedStart")))
        assert start == datetime(2026, 12, 7, 6, 0, tzinfo=UTC) + timedelta(minutes=beam["start"])
    first, second = members
    f.state(first, orders[first], ActionStatus.RUNNING)
    assert f.reports(run["id"]) == {"beam": "started"}
    f.state(first, orders[first], ActionStatus.FINISHED)
    assert f.reports(run["id"]) == {"beam": "started"}  # one member is not the team
    f.state(second, orders[second], ActionStatus.FINISHED)
    assert f.reports(run["id"]) == {"beam": "done"}


def test_orders_changed_in_the_middle_of_a_state_does_not_lose_it(
    fleet: tuple[TestClient, Fleet, str, list[str]],
) -> None:
    # The bridge's loop cleared the intake's memo of orders while a state read them (a
    # KeyError that stopped every later message): the clear lands here at the same point,
    # as the orders just read leave their session.
    _, f, run_id, robots = fleet
    robot = robots[0]
    f.connection(robot, ConnectionState.ONLINE)
    order = _orders(f.dispatch())[robot]
    cleared: list[object] = []

    def clear(session: object, instance: object) -> None:
        if isinstance(instance, FleetOrder) and not cleared:
            cleared.append(instance)
            f.intake.orders_changed()

    event.listen(f.sessions, "persistent_to_detached", clear)
    try:
        assert f.state(robot, order, ActionStatus.FINISHED) is None
    finally:
        event.remove(f.sessions, "persistent_to_detached", clear)
    assert cleared, "the memo was never cleared mid-read: the test no longer reaches the race"
    action = order.task_actions()[0].action_id
    assert f.reports(run_id)[action] == "done"


def test_a_plan_made_before_the_fleet_began_goes_out_once_revised(
    fleet: tuple[TestClient, Fleet, str, list[str]],
) -> None:
    """docs/fleet.md#task-to-order: the store's fleet began after this run was made."""
    client, f, run_id, robots = fleet
    f.names = replace(f.names, since=utcnow())
    f.intake.names = f.names
    for robot in robots:
        f.connection(robot, ConnectionState.ONLINE)
    assert f.dispatch() == []
    # A robot gone does not revise it either: it is not a plan of the fleet.
    assert f.connection(robots[0], ConnectionState.OFFLINE) is None
    assert client.get(f"/runs/{run_id}").json()["superseded_by"] is None
    # Revised now, it is.
    head = revise(
        client,
        run_id,
        {**HEAVY_DOWN, "changes": [{"type": "robot_unavailable", "robot": robots[0]}]},
    )["id"]
    wait_status(client, head, "completed")
    orders = _orders(f.dispatch())
    assert sorted(orders) == robots[1:]
    assert all(o.order_id.startswith(f"{run_id}:") for o in orders.values())


def test_the_last_robot_gone_leaves_the_plan_as_it_is(
    fleet: tuple[TestClient, Fleet, str, list[str]], caplog: pytest.LogCaptureFixture
) -> None:
    """docs/fleet.md#no-robot-left."""
    client, f, run_id, robots = fleet
    for robot in robots:
        f.connection(robot, ConnectionState.ONLINE)
    f.dispatch()
    head = run_id
    for robot in robots[:-1]:
        f.connection(robot, ConnectionState.OFFLINE)
        head = wait_status(client, head, "completed")["superseded_by"]
        assert head is not None
        wait_status(client, head, "completed")
    last = robots[-1]
    assert f.connection(last, ConnectionState.OFFLINE) is None
    assert client.get(f"/runs/{head}").json()["superseded_by"] is None
    assert any(f"robot '{last}' was the last" in m for m in caplog.messages)
    left = client.get(f"/runs/{head}").json()["assignments"]
    assert {a["robot"] for a in left if not a.get("pinned")} <= {last}


def test_a_store_whose_bridge_sent_orders_before_its_row_goes_on_serving_them(
    fleet: tuple[TestClient, Fleet, str, list[str]],
) -> None:
    """An upgrade: the fleet began with the first lineage the bridge sent (app.fleet.lease)."""
    client, f, _, robots = fleet
    robot = robots[0]
    f.connection(robot, ConnectionState.ONLINE)
    first = _orders(f.dispatch())[robot]
    settings = client.app.state.settings  # type: ignore[attr-defined]
    standing = LocalLease(settings=settings, sessions=f.sessions).prepare("id-upgraded")
    f.names = replace(f.names, since=standing.since)
    f.intake.names = f.names
    assert f.state(robot, first, ActionStatus.FINISHED) is None
    assert list(_orders(f.dispatch())) == [robot]
