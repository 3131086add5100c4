"""Where an order stands in the bridge's books (docs/fleet.md#task-to-order)."""

from __future__ import annotations

from enum import StrEnum


class OrderState(StrEnum):
    SENT = "sent"  # published (or in the outbox), the robot's current work
    FINISHED = "finished"  # its action FINISHED
    FAILED = "failed"  # its action FAILED
    CANCELLED = "cancelled"  # a revision took the task from the robot: cancelOrder sent


OPEN = frozenset({OrderState.SENT})


class Refusal(StrEnum):
    """Why a robot's message was refused (counted, logged, never stored)."""

    MALFORMED = "malformed"  # not JSON, not VDA 5050, or its header names another robot
    FOREIGN_TOPIC = "foreign_topic"  # not {interface}/v2/{manufacturer}/{serial}/{topic}
    UNKNOWN_ROBOT = "unknown_robot"  # a state from a robot that never said ONLINE
    UNKNOWN_ORDER = "unknown_order"  # an orderId the bridge never sent that robot
    REPLAYED = "replayed"  # a headerId already seen on that topic
    OUT_OF_ORDER = "out_of_order"  # a timestamp before the last one accepted on that topic
    REPORT_REFUSED = "report_refused"  # the execution report it implies was refused
