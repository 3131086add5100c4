"""A fleet of simulated VDA 5050 vehicles (`ltaa fleet simulate`, docs/fleet.md#the-simulator),
for tests and demos: a separate process that talks MQTT, so whatever drives it exercises a real
broker.

Each robot is its own MQTT client, with a last will of `connection` CONNECTIONBROKEN (retained)
and `connection` ONLINE (retained) once connected. It takes `order`s (the same orderId and
orderUpdateId twice is ignored, a newer orderUpdateId replaces the order) and runs each action
in turn: RUNNING for its `plannedDurationS` divided by the speed (planned seconds a robot works
through per second: 600 makes a planned minute a tenth of a second) or, when the order plans no
duration, the default seconds; then FINISHED, or FAILED for the given share of actions, drawn
from a seeded generator per robot.
`cancelOrder` fails the running action and drops the order. It publishes its `state` every
`state_interval_s` and at every change, headerIds counting per topic, the battery draining.

Commands on standard input, one a line: `break NAME` (the robot's socket is closed without a
DISCONNECT, so the broker publishes its will), `offline NAME` (a clean OFFLINE), `quit`. The end
of standard input ends the commands, not the robots (`... < /dev/null &` keeps them working):
`quit`, SIGTERM or SIGINT stops them, each saying OFFLINE. Each event is a line on standard
output (`robot-3 FINISHED t17`), for whoever waits on one.
"""

from __future__ import annotations

import random
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from types import FrameType
from urllib.parse import urlsplit

import paho.mqtt.client as mqtt
from pydantic import ValidationError

from app.fleet.vda5050 import (
    CANCEL_ORDER,
    ORDER_ID,
    PLANNED_DURATION_S,
    PROTOCOL_VERSION,
    Action,
    ActionState,
    ActionStatus,
    BatteryState,
    Connection,
    ConnectionState,
    InstantActions,
    Order,
    SafetyState,
    State,
    Topic,
    topic,
)


@dataclass(frozen=True)
class SimulatorConfig:
    url: str
    interface: str = "uagv"
    manufacturer: str = "ltaa-sim"
    names: tuple[str, ...] = ("robot-1", "robot-2", "robot-3")
    speed: float = 1.0  # planned seconds worked through per second
    fail_share: float = 0.0
    seed: int = 0
    default_duration_s: float = 1.0
    state_interval_s: float = 1.0
    drain_per_s: float = 0.01  # battery percent per second of work


@dataclass
class _Running:
    order: Order
    actions: list[Action]
    states: dict[str, ActionStatus] = field(default_factory=dict)
    index: int = 0
    ends_at: float | None = None


class SimulatedRobot:
    """One vehicle: its own MQTT client and its own thread of work."""

    def __init__(self, config: SimulatorConfig, name: str, say: Callable[[str], None]) -> None:
        self.config, self.name, self.say = config, name, say
        self.random = random.Random(f"{config.seed}:{name}")
        self.headers: dict[Topic, int] = {}
        self.lock = threading.RLock()
        self.current: _Running | None = None
        self.seen: set[tuple[str, int]] = set()
        self.battery = 100.0
        self.stopped = threading.Event()
        self.client = mqtt.Client(
            mqtt.CallbackAPIVersion.VERSION2, client_id=f"{config.interface}-{name}"
        )
        self.client.will_set(
            self._topic(Topic.CONNECTION),
            self._connection(ConnectionState.CONNECTIONBROKEN, count=False),
            qos=1,
            retain=True,
        )
        self.client.on_connect = self._on_connect
        self.client.on_message = self._on_message

    # -- MQTT --------------------------------------------------------------------------

    def _topic(self, kind: Topic) -> str:
        return topic(self.config.interface, self.config.manufacturer, self.name, kind)

    def _header(self, kind: Topic) -> int:
        self.headers[kind] = self.headers.get(kind, -1) + 1
        return self.headers[kind]

    def _connection(self, state: ConnectionState, *, count: bool = True) -> bytes:
        # The will is written before the first message: it takes the next header then.
        header = (
            self._header(Topic.CONNECTION) if count else self.headers.get(Topic.CONNECTION, 0) + 1
        )
        return Connection(
            header_id=header,
            timestamp=datetime.now(UTC),
            version=PROTOCOL_VERSION,
            manufacturer=self.config.manufacturer,
            serial_number=self.name,
            connection_state=state,
        ).wire()

    def start(self) -> None:
        parts = urlsplit(self.config.url)
        self.client.connect(parts.hostname or "127.0.0.1", parts.port or 1883, keepalive=5)
        self.client.loop_start()
        threading.Thread(target=self._work, name=f"sim-{self.name}", daemon=True).start()

    def _on_connect(self, client: mqtt.Client, *_args: object) -> None:
        client.subscribe([(self._topic(Topic.ORDER), 1), (self._topic(Topic.INSTANT_ACTIONS), 1)])
        client.publish(
            self._topic(Topic.CONNECTION), self._connection(ConnectionState.ONLINE), 1, True
        )
        self.say(f"{self.name} ONLINE")
        self.publish_state()

    def _on_message(
        self, _client: mqtt.Client, _userdata: object, message: mqtt.MQTTMessage
    ) -> None:
        try:
            if message.topic.endswith("/" + Topic.ORDER.value):
                self._take(Order.model_validate_json(message.payload))
            elif message.topic.endswith("/" + Topic.INSTANT_ACTIONS.value):
                self._instant(InstantActions.model_validate_json(message.payload))
        except ValidationError as exc:  # a robot ignores what it cannot read
            self.say(f"{self.name} REFUSED {exc.errors()[0]['msg']}")

    def publish_state(self) -> None:
        with self.lock:
            run = self.current
            states = []
            if run is not None:
                states = [
                    ActionState(
                        action_id=a.action_id,
                        action_type=a.action_type,
                        action_status=run.states.get(a.action_id, ActionStatus.WAITING),
                    )
                    for a in run.actions
                ]
            state = State(
                header_id=self._header(Topic.STATE),
                timestamp=datetime.now(UTC),
                version=PROTOCOL_VERSION,
                manufacturer=self.config.manufacturer,
                serial_number=self.name,
                order_id=run.order.order_id if run else "",
                order_update_id=run.order.order_update_id if run else 0,
                last_node_id=run.order.nodes[0].node_id if run and run.order.nodes else "",
                last_node_sequence_id=0,
                node_states=[],
                edge_states=[],
                driving=False,
                action_states=states,
                battery_state=BatteryState(battery_charge=round(self.battery, 2), charging=False),
                operating_mode="AUTOMATIC",
                errors=[],
                safety_state=SafetyState(),
            )
            self.client.publish(self._topic(Topic.STATE), state.wire(), 1)

    # -- work --------------------------------------------------------------------------

    def _take(self, order: Order) -> None:
        key = (order.order_id, order.order_update_id)
        with self.lock:
            if key in self.seen:
                return  # VDA 5050: the same order again is ignored
            self.seen.add(key)
            keep = (
                self.current.states
                if self.current is not None and self.current.order.order_id == order.order_id
                else {}
            )
            actions = order.task_actions()
            self.current = _Running(order, actions, dict(keep))
            self.say(f"{self.name} ORDER {order.order_id} {order.order_update_id}")
        self.publish_state()

    def _instant(self, message: InstantActions) -> None:
        for action in message.actions:
            if action.action_type != CANCEL_ORDER:
                continue
            with self.lock:
                run = self.current
                if run is None or run.order.order_id != action.parameter(ORDER_ID):
                    continue
                for a in run.actions:
                    if run.states.get(a.action_id) != ActionStatus.FINISHED:
                        run.states[a.action_id] = ActionStatus.FAILED
                self.say(f"{self.name} CANCELLED {run.order.order_id}")
            self.publish_state()
            with self.lock:
                self.current = None

    def _work(self) -> None:
        last_state = time.monotonic()
        while not self.stopped.is_set():
            changed = self._step()
            now = time.monotonic()
            if changed or now - last_state >= self.config.state_interval_s:
                if self.client.is_connected():
                    self.publish_state()
                last_state = now
            time.sleep(0.02)

    def _step(self) -> bool:
        """Advance the current order; whether an action changed status."""
        with self.lock:
            run = self.current
            if run is None:
                return False
            if run.index >= len(run.actions):
                return False
            action = run.actions[run.index]
            status = run.states.get(action.action_id)
            if status in (ActionStatus.FINISHED, ActionStatus.FAILED):
                run.index += 1
                return False
            now = time.monotonic()
            if status != ActionStatus.RUNNING:
                planned = action.parameter(PLANNED_DURATION_S)
                seconds = (
                    float(planned) / self.config.speed
                    if planned is not None
                    else self.config.default_duration_s
                )
                run.states[action.action_id] = ActionStatus.RUNNING
                run.ends_at = now + seconds
                self.say(f"{self.name} RUNNING {action.action_id}")
                return True
            if run.ends_at is not None and now >= run.ends_at:
                failed = self.random.random() < self.config.fail_share
                done = ActionStatus.FAILED if failed else ActionStatus.FINISHED
                run.states[action.action_id] = done
                self.battery = max(0.0, self.battery - self.config.drain_per_s)
                self.say(f"{self.name} {done.value} {action.action_id}")
                return True
            return False

    # -- leaving -----------------------------------------------------------------------

    def break_connection(self) -> None:
        """Drop the socket without DISCONNECT: the broker publishes the will."""
        self.stopped.set()
        sock = self.client.socket()
        self.client.loop_stop()
        if sock is not None:
            sock.close()
        self.say(f"{self.name} BROKEN")

    def go_offline(self) -> None:
        self.stopped.set()
        info = self.client.publish(
            self._topic(Topic.CONNECTION), self._connection(ConnectionState.OFFLINE), 1, True
        )
        info.wait_for_publish(timeout=5)
        self.client.disconnect()
        self.client.loop_stop()
        self.say(f"{self.name} OFFLINE")


class Stopped(Exception):
    """SIGTERM or SIGINT: the robots say OFFLINE and the simulator ends."""


def _stop(_signum: int, _frame: FrameType | None) -> None:
    raise Stopped


def simulate(config: SimulatorConfig, commands: Sequence[str] | None = None) -> None:
    """Run the robots, taking commands from `commands` (default: standard input) until `quit`,
    then until SIGTERM or SIGINT: every robot goes OFFLINE then."""
    out_lock = threading.Lock()

    def say(line: str) -> None:
        with out_lock:
            print(line, flush=True)

    robots = {name: SimulatedRobot(config, name, say) for name in config.names}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, _stop)
    try:
        for robot in robots.values():
            robot.start()
        if _obey(commands if commands is not None else sys.stdin, robots, say):
            say("end of commands; the robots work on until SIGTERM or SIGINT")
            threading.Event().wait()
    except Stopped:
        pass
    finally:
        for robot in robots.values():
            if not robot.stopped.is_set():
                robot.go_offline()


def _obey(
    lines: Iterable[str], robots: Mapping[str, SimulatedRobot], say: Callable[[str], None]
) -> bool:
    """Carry out the commands; True when they ran out without a `quit`."""
    for line in lines:
        words = line.split()
        if not words:
            continue
        if words[0] == "quit":
            return False
        target = robots.get(words[1]) if len(words) > 1 else None
        if target is None:
            say(f"unknown command or robot: {line.strip()}")
        elif words[0] == "break":
            target.break_connection()
        elif words[0] == "offline":
            target.go_offline()
        else:
            say(f"unknown command: {line.strip()}")
    return True
