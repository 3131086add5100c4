"""The node gate: a hold waits for node bodies in flight and keeps new ones out."""

from __future__ import annotations

import threading
import time

import pytest

from app.graph.gate import GateTimeoutError, NodeGate


def test_a_hold_waits_for_the_body_in_flight_and_blocks_the_next() -> None:
    gate = NodeGate()
    inside, release, log = threading.Event(), threading.Event(), []

    def node(name: str, wait: bool) -> None:
        with gate.passage():
            log.append(f"{name} in")
            if wait:
                inside.set()
                release.wait(5)
            log.append(f"{name} out")

    first = threading.Thread(target=node, args=("first", True))
    first.start()
    inside.wait(5)
    held = threading.Event()

    def hold() -> None:
        with gate.held(timeout_s=5) as waited_for:
            assert waited_for == 1
            log.append("held")
            held.set()
            time.sleep(0.2)
            second = threading.Thread(target=node, args=("second", False))
            second.start()
            time.sleep(0.2)
            log.append("released")
        second.join(5)

    holder = threading.Thread(target=hold)
    holder.start()
    time.sleep(0.1)
    assert not held.is_set()  # still waiting for the first body
    release.set()
    holder.join(5)
    first.join(5)
    assert log == ["first in", "first out", "held", "released", "second in", "second out"]


def test_a_hold_times_out_and_lets_nodes_go_on() -> None:
    gate = NodeGate()
    release = threading.Event()
    entered = threading.Event()

    def stuck() -> None:
        with gate.passage():
            entered.set()
            release.wait(5)

    t = threading.Thread(target=stuck)
    t.start()
    entered.wait(5)
    with pytest.raises(GateTimeoutError), gate.held(timeout_s=0.1):
        pass
    release.set()
    t.join(5)
    with gate.passage():  # not left held by the failed hold
        pass
