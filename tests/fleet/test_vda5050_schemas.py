"""The VDA 5050 schemas the fleet tests check against are the official 2.1.0 files, and the
service's message shapes (app.fleet.vda5050) produce messages they accept."""

from __future__ import annotations

import hashlib
import json
from datetime import UTC, datetime
from typing import Any

import jsonschema
import pytest

from app.fleet.vda5050 import (
    PROTOCOL_VERSION,
    Action,
    ActionParameter,
    Connection,
    ConnectionState,
    InstantActions,
    Node,
    Order,
)
from tests.support.vda5050_schemas import schema_bytes, validate

# sha256 of json_schemas/*.schema in VDA5050/VDA5050 at tag 2.1.0 (the shipped copies).
OFFICIAL = {
    "order": "18fedf85ecf7bc22baf7da71b74d08d699d65b8c6a5f0ccde8bc8d84e1406796",
    "state": "26e41279414d7acfeac6ea9b6438b484b0930ee0e9059cf953168d141da8473b",
    "instantActions": "79b9d71ce31f5bce167d470e0e12a83c28f28f20580148b4dae28cedeb78a355",
    "connection": "aa991bc8c5a15115a3cb46cbbc2a87bef208cef436268a06feed663a949c30f1",
    "factsheet": "386e3f20be0fa29132e8b3bc1e90991e7e5cf496aae7f3fb744cb072174a8bfc",
}
HEADER: dict[str, Any] = {
    "header_id": 3,
    "timestamp": datetime(2026, 12, 5, 8, 0, tzinfo=UTC),
    "version": PROTOCOL_VERSION,
    "manufacturer": "acme",
    "serial_number": "robot-1",
}


@pytest.mark.parametrize("kind", sorted(OFFICIAL))
def test_the_schemas_are_the_official_2_1_0_files(kind: str) -> None:
    assert hashlib.sha256(schema_bytes(kind)).hexdigest() == OFFICIAL[kind]


def test_our_messages_validate() -> None:
    action = Action(
        action_type="drywall",
        action_id="T1",
        action_parameters=[ActionParameter(key="taskId", value="T1")],
    )
    order = Order(
        **HEADER,
        order_id="r:T1:robot-1",
        order_update_id=0,
        nodes=[Node(node_id="zone-a", sequence_id=0, actions=[action])],
    )
    validate("order", json.loads(order.wire()))
    cancel = InstantActions(
        **HEADER, actions=[action.model_copy(update={"action_type": "cancelOrder"})]
    )
    validate("instantActions", json.loads(cancel.wire()))
    hello = Connection(**HEADER, connection_state=ConnectionState.ONLINE)
    validate("connection", json.loads(hello.wire()))


def test_the_schema_check_refuses_a_bad_message() -> None:
    hello = json.loads(Connection(**HEADER, connection_state=ConnectionState.ONLINE).wire())
    with pytest.raises(jsonschema.ValidationError):
        validate("connection", {**hello, "connectionState": "ASLEEP"})
    with pytest.raises(jsonschema.ValidationError):
        validate("connection", {k: v for k, v in hello.items() if k != "headerId"})
