"""A process-wide gate every node passes through, so that a backup can hold all runs at a
node boundary while it copies both SQLite files.

A node writes the app tables (decisions, attempts) and the checkpointer saves the state
after it; copying the two files while nodes run would give a pair that disagrees by
however many tasks ran between the two copies. Held, the gate lets running node bodies
finish and no new one start, so the copies are of one moment between nodes.

Process-wide on purpose: the runs of a process share its two files, so one gate per
process is the unit a backup needs (a gate per worker would miss `ltaa run`'s).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager


class GateTimeoutError(RuntimeError):
    """Node bodies were still running when the hold's wait ran out."""


class NodeGate:
    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._holds = 0
        self._inside = 0

    @contextmanager
    def passage(self) -> Iterator[None]:
        """Around a node body: waits while the gate is held."""
        with self._cond:
            while self._holds:
                self._cond.wait()
            self._inside += 1
        try:
            yield
        finally:
            with self._cond:
                self._inside -= 1
                self._cond.notify_all()

    @contextmanager
    def held(self, timeout_s: float = 120.0) -> Iterator[int]:
        """No node body runs inside this block; yields how many the hold waited for. An LLM
        call in flight is waited for (it is one node body), up to timeout_s."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            self._holds += 1
            waited_for = self._inside
            try:
                while self._inside:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        raise GateTimeoutError(
                            f"{self._inside} node(s) still running after {timeout_s:g} s"
                        )
                    self._cond.wait(left)
            except BaseException:
                self._holds -= 1
                self._cond.notify_all()
                raise
        try:
            yield waited_for
        finally:
            with self._cond:
                self._holds -= 1
                self._cond.notify_all()


NODE_GATE = NodeGate()
