"""The test-only pause points: parsed strictly, wrap only their node, and a held run leaves
through the recorder's stop check (a cancel or the server draining)."""

from __future__ import annotations

import threading
import time

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
from tests.unit.ltaa_support import problem


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
def test_a_held_run_stops_at_the_point_and_leaves_on_cancel(after: bool) -> None:
    rec = MemoryRecorder()
    ctx = GraphContext(problem=problem(), reasoner=RulesReasoner(), recorder=rec)
    hook = pause_hook(PausePoint(4, "store_and_route", after=after), frozenset(NODES))
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
    deadline = time.monotonic() + 10
    while len(rec.decisions()) < stored and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.3)
    assert thread.is_alive()  # held, not finished
    assert [d.task_index for d in rec.decisions()] == list(range(stored))
    rec.cancel()
    thread.join(timeout=5)
    assert not thread.is_alive()
    assert len(outcome) == 1 and isinstance(outcome[0], RunCancelled)
