"""The pause hook: an explicit test and operations hook that holds a run at one node of one
task, so an end-to-end test can SIGKILL (or SIGTERM) the server at a known place anywhere
in the graph (docs/operations.md#the-pause-hook-ltaa_test_pause).

It is inert unless `LTAA_TEST_PAUSE` is set: app.runs.factory.pause_hook_from_settings then
returns no hook and build_graph adds every node unwrapped; nothing here runs in a run. Set,
the server warns at start-up, and each held run logs `PausePoint.message()`, which the
tests wait for (tests/support/server.py). It stays in the product because the server process
that is killed must install it; in-process tests pass `pause_hook(...)` to the worker.

`<node>:before` holds the node before its body runs: this node has done nothing.
`<node>:after` holds it once its body has run and its side effects are recorded, but
before LangGraph takes the step's checkpoint: the window in which a crash makes the node
run again from its top, which is where a non-idempotent side effect would show. (The
worker's saver writes a checkpoint where each task begins, so a crash at either point
re-runs the task's nodes from its start: app.graph.checkpoint._sparse.)

A held run waits, polling `Recorder.check_cancelled`, until the process dies or the run is
stopped (a cancel or the server draining raises RunCancelled out of the hold).
"""

from __future__ import annotations

import functools
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from langgraph.runtime import Runtime

from app.graph.state import GraphContext, LTAAState, Node

log = logging.getLogger("ltaa.runs")


NodeHook = Callable[[str, Node], Node]
POLL_S = 0.05


@dataclass(frozen=True)
class PausePoint:
    task_index: int
    node: str
    after: bool

    @classmethod
    def parse(cls, task_index: int, spec: str) -> PausePoint:
        """`spec` is `<node>:before` or `<node>:after` (a bare `<node>` means after)."""
        node, _, when = spec.partition(":")
        if when not in ("", "before", "after"):
            raise ValueError(f"pause point {spec!r}: write <node>:before or <node>:after")
        return cls(task_index=task_index, node=node, after=when != "before")

    @classmethod
    def from_setting(cls, value: str) -> PausePoint:
        """`LTAA_TEST_PAUSE`: `<task index>:<node>:<before|after>`."""
        task, _, spec = value.partition(":")
        if not task.isdigit() or spec.count(":") != 1:
            raise ValueError(f"LTAA_TEST_PAUSE={value!r}: write <task index>:<node>:<before|after>")
        return cls.parse(int(task), spec)

    def message(self) -> str:
        """The log line's text; end-to-end tests wait for it before killing the server."""
        return (
            f"test pause: holding task {self.task_index} "
            f"{'after' if self.after else 'before'} {self.node}"
        )


def pause_hook(point: PausePoint, node_names: frozenset[str]) -> NodeHook:
    """A build_graph node hook that wraps only the node named by `point`."""
    if point.node not in node_names:
        raise ValueError(
            f"pause point names node {point.node!r}; the graph's nodes are "
            f"{', '.join(sorted(node_names))}"
        )

    def hook(name: str, node: Node) -> Node:
        if name != point.node:
            return node

        @functools.wraps(node)
        def held(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
            hit = state["task_index"] == point.task_index
            if hit and not point.after:
                _hold(point, runtime.context)
            update = node(state, runtime)
            if hit and point.after:
                _hold(point, runtime.context)
            return update

        return held

    return hook


def _hold(point: PausePoint, context: GraphContext) -> None:
    log.warning("%s", point.message())
    while True:
        context.recorder.check_cancelled()
        time.sleep(POLL_S)
