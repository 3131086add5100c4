"""The test-only pause points: parsed strictly, wrap only their node, and a held run leaves
through the recorder's stop check (a cancel or the server draining)."""

from __future__ import annotations

import logging
import threading
from typing import Any

import pytest
from langgraph.checkpoint.memory import InMemorySaver
from pydantic import ValidationError

from app.config import Settings
from app.graph.builder import NODES, build_graph
from app.graph.memory_recorder import MemoryRecorder
from app.graph.pause import PausePoint, pause_hook
from app.graph.recorder import RunCancelled
from app.graph.runner import run_graph
from app.graph.state import GraphContext
from app.reasoners.rules import RulesReasoner
from tests.support.ltaa_support import problem
from tests.support.polling import eventually, wait_logged


class StopCheckCounter(MemoryRecorder):
    """Counts the stop checks: a held run keeps making them while it stores nothing."""

    def __init__(self) -> None:
        super().__init__()
        self.stop_checks = 0

    def check_cancelled(self) -> None:
        self.stop_checks += 1
        super().check_cancelled()


def test_parse() -> None:
    assert PausePoint.parse(3, "validate:before") == PausePoint(3, "validate", after=False)
    assert PausePoint.parse(3, "validate") == PausePoint(3, "validate", after=True)
    with pytest.raises(ValueError, match="<node>:before or <node>:after"):
        PausePoint.parse(3, "validate:during")
    with pytest.raises(ValueError, match="the graph's nodes are"):
        pause_hook(PausePoint(3, "validation", after=True), frozenset(NODES))


def test_setting_is_checked() -> None:
    assert Settings(test_pause="3:reason:after").test_pause == "3:reason:after"
    with pytest.raises(ValidationError):
        Settings(test_pause="3:reason at the end")


@pytest.mark.parametrize("after", [False, True])
def test_a_held_run_stops_at_the_point_and_leaves_on_cancel(
    after: bool, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="ltaa.runs")
    rec = StopCheckCounter()
    ctx = GraphContext(problem=problem(), reasoner=RulesReasoner(), recorder=rec)
    point = PausePoint(4, "store_and_route", after=after)
    hook = pause_hook(point, frozenset(NODES))
    graph = build_graph(InMemorySaver(), node_hook=hook)
    outcome: list[BaseException] = []

    def run() -> None:
        try:
            run_graph(graph, ctx, "held", resume=False)
        except BaseException as exc:  # handed to the test thread
            outcome.append(exc)

    thread = threading.Thread(target=run)
    thread.start()
    # `after`: task 4's decision is stored by the held node; `before`: not yet.
    stored = 5 if after else 4
    wait_logged(caplog, point.message(), timeout=10)
    # Held, not passing through: a graph going on makes one stop check per node and stores
    # a decision at least every seven nodes, so eight more checks with the decisions as
    # they were mean the run is waiting in the hold.
    checks = rec.stop_checks
    eventually(
        lambda: rec.stop_checks,
        until=lambda n: n >= checks + 8,
        timeout=10,
        what="the held run polling its stop check eight more times",
    )
    assert thread.is_alive()  # held, not finished
    assert [d.task_index for d in rec.decisions()] == list(range(stored))
    rec.cancel()
    thread.join(timeout=5)
    assert not thread.is_alive()
    assert len(outcome) == 1 and isinstance(outcome[0], RunCancelled)


def _node_function(graph: Any, name: str) -> object:
    """The function LangGraph runs for a node (its RunnableCallable's `func`)."""
    return getattr(graph.builder.nodes[name].runnable, "func", None)


def test_the_hook_is_inert_unless_set(caplog: pytest.LogCaptureFixture) -> None:
    from app.runs.factory import pause_hook_from_settings

    with caplog.at_level(logging.WARNING, logger="ltaa.runs"):
        assert pause_hook_from_settings(Settings(test_pause=None)) is None
    assert "LTAA_TEST_PAUSE" not in caplog.text
    graph = build_graph(node_hook=None)
    # Every node is the graph's own function, unwrapped.
    assert {name: _node_function(graph, name) for name in NODES} == NODES
    with caplog.at_level(logging.WARNING, logger="ltaa.runs"):
        hook = pause_hook_from_settings(Settings(test_pause="3:reason:before"))
    assert hook is not None and "LTAA_TEST_PAUSE is set" in caplog.text
    held = build_graph(node_hook=hook)
    assert _node_function(held, "reason") is not NODES["reason"]
    assert _node_function(held, "validate") is NODES["validate"]
