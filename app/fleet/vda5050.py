"""The VDA 5050 2.1 messages the fleet bridge and the simulator exchange (docs/fleet.md).

One shape per message, in the protocol's own camelCase on the wire: the bridge builds
`Order` and `InstantActions` and reads `State` and `Connection`; the simulator does the
reverse with the same classes, so the two can never disagree on a field. Only the fields
the service uses are typed; the rest of a robot's message is kept as sent (extra="allow")
and ignored. Every message published is checked against the official JSON schemas in the
tests (tests/support/vda5050_schemas.py).
"""

from __future__ import annotations

from datetime import UTC, datetime
from enum import StrEnum
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_serializer

PROTOCOL_VERSION = "2.1.0"
MAJOR = "v2"


class Topic(StrEnum):
    ORDER = "order"
    INSTANT_ACTIONS = "instantActions"
    STATE = "state"
    CONNECTION = "connection"


class ConnectionState(StrEnum):
    ONLINE = "ONLINE"
    OFFLINE = "OFFLINE"
    CONNECTIONBROKEN = "CONNECTIONBROKEN"


class ActionStatus(StrEnum):
    WAITING = "WAITING"
    INITIALIZING = "INITIALIZING"
    RUNNING = "RUNNING"
    FINISHED = "FINISHED"
    FAILED = "FAILED"


class ErrorLevel(StrEnum):
    WARNING = "WARNING"
    FATAL = "FATAL"


class BlockingType(StrEnum):
    NONE = "NONE"
    SOFT = "SOFT"
    HARD = "HARD"


# actionParameters keys the bridge writes on a task's action (docs/fleet.md#task-to-order).
TASK_ID = "taskId"
RUN_ID = "runId"
PLANNED_START = "plannedStart"
PLANNED_END = "plannedEnd"
PLANNED_DURATION_S = "plannedDurationS"
CANCEL_ORDER = "cancelOrder"
ORDER_ID = "orderId"


def topic(interface: str, manufacturer: str, serial_number: str, kind: Topic) -> str:
    """`{interface}/{major}/{manufacturer}/{serialNumber}/{topic}`, as VDA 5050 names it."""
    return f"{interface}/{MAJOR}/{manufacturer}/{serial_number}/{kind.value}"


def subscription(interface: str, kind: Topic) -> str:
    """Every robot's messages of one kind."""
    return f"{interface}/{MAJOR}/+/+/{kind.value}"


def parse_topic(interface: str, name: str) -> tuple[str, str, Topic] | None:
    """(manufacturer, serialNumber, kind) of a topic under the interface; None otherwise."""
    parts = name.split("/")
    if len(parts) != 5 or parts[0] != interface or parts[1] != MAJOR:
        return None
    try:
        return parts[2], parts[3], Topic(parts[4])
    except ValueError:
        return None


def timestamp(at: datetime) -> str:
    """ISO 8601 in UTC with milliseconds and a Z, as the protocol's examples write it."""
    aware = at if at.tzinfo is not None else at.replace(tzinfo=UTC)
    return aware.astimezone(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


class Message(BaseModel):
    """Fields every VDA 5050 message starts with."""

    model_config = ConfigDict(populate_by_name=True, extra="allow", frozen=True)

    header_id: int = Field(alias="headerId", ge=0)
    timestamp: datetime
    version: str
    manufacturer: str = Field(min_length=1)
    serial_number: str = Field(alias="serialNumber", min_length=1)

    @field_serializer("timestamp")
    def _timestamp(self, at: datetime) -> str:
        return timestamp(at)

    def wire(self) -> bytes:
        """The JSON published on the broker."""
        return self.model_dump_json(by_alias=True, exclude_none=True).encode()

    def model_post_init(self, context: Any) -> None:
        if self.timestamp.tzinfo is None:
            # A robot's clock without an offset cannot be put in order with the others.
            raise ValueError("timestamp must carry a time zone (VDA 5050 sends UTC, ...Z)")


class ActionParameter(BaseModel):
    model_config = ConfigDict(frozen=True)

    key: str
    value: str | float | bool | list[Any] | dict[str, Any]


class Action(BaseModel):
    model_config = ConfigDict(populate_by_name=True, extra="allow", frozen=True)

    action_type: str = Field(alias="actionType", min_length=1)
    action_id: str = Field(alias="actionId", min_length=1)
    blocking_type: BlockingType = Field(BlockingType.HARD, alias="blockingType")
    action_description: str | None = Field(None, alias="actionDescription")
    action_parameters: list[ActionParameter] = Field(default_factory=list, alias="actionParameters")

    def parameter(self, key: str) -> Any:
        return next((p.value for p in self.action_parameters if p.key == key), None)


class NodePosition(BaseModel):
    model_config = ConfigDict(populate_by_name=True, frozen=True)

    x: float
    y: float
    map_id: str = Field(alias="mapId")


class Node(BaseModel):
    model_config = ConfigDict(populate_by_name=True, extra="allow", frozen=True)

    node_id: str = Field(alias="nodeId", min_length=1)
    sequence_id: int = Field(alias="sequenceId", ge=0)
    released: bool = True
    node_position: NodePosition | None = Field(None, alias="nodePosition")
    actions: list[Action] = Field(default_factory=list)


class Order(Message):
    order_id: str = Field(alias="orderId", min_length=1)
    order_update_id: int = Field(alias="orderUpdateId", ge=0)
    nodes: list[Node]
    # One node per order (the task's zone): no edge to drive along.
    edges: list[dict[str, Any]] = Field(default_factory=list)

    def task_actions(self) -> list[Action]:
        return [a for node in self.nodes for a in node.actions]


class InstantActions(Message):
    actions: list[Action]


class ActionState(BaseModel):
    model_config = ConfigDict(populate_by_name=True, extra="allow", frozen=True)

    action_id: str = Field(alias="actionId", min_length=1)
    action_status: ActionStatus = Field(alias="actionStatus")
    action_type: str | None = Field(None, alias="actionType")
    result_description: str | None = Field(None, alias="resultDescription")


class BatteryState(BaseModel):
    model_config = ConfigDict(populate_by_name=True, extra="allow", frozen=True)

    battery_charge: float = Field(alias="batteryCharge")
    charging: bool


class RobotError(BaseModel):
    model_config = ConfigDict(populate_by_name=True, extra="allow", frozen=True)

    error_type: str = Field(alias="errorType")
    error_level: ErrorLevel = Field(alias="errorLevel")
    error_description: str | None = Field(None, alias="errorDescription")


class SafetyState(BaseModel):
    model_config = ConfigDict(populate_by_name=True, frozen=True)

    e_stop: Literal["AUTOACK", "MANUAL", "REMOTE", "NONE"] = Field("NONE", alias="eStop")
    field_violation: bool = Field(False, alias="fieldViolation")


class State(Message):
    order_id: str = Field(alias="orderId")  # "" while the robot has no order
    order_update_id: int = Field(alias="orderUpdateId", ge=0)
    last_node_id: str = Field(alias="lastNodeId")
    last_node_sequence_id: int = Field(alias="lastNodeSequenceId", ge=0)
    node_states: list[dict[str, Any]] = Field(alias="nodeStates")
    edge_states: list[dict[str, Any]] = Field(alias="edgeStates")
    driving: bool
    action_states: list[ActionState] = Field(alias="actionStates")
    battery_state: BatteryState = Field(alias="batteryState")
    operating_mode: Literal["AUTOMATIC", "SEMIAUTOMATIC", "MANUAL", "SERVICE", "TEACHIN"] = Field(
        alias="operatingMode"
    )
    errors: list[RobotError]
    safety_state: SafetyState = Field(alias="safetyState")

    def fatal(self) -> list[RobotError]:
        return [e for e in self.errors if e.error_level == ErrorLevel.FATAL]


class Connection(Message):
    connection_state: ConnectionState = Field(alias="connectionState")
