"""An in-memory Recorder: for the synchronous `ltaa` solver and for tests.

Records are copied in and out, as a database would, so a node that mutates what it read
changes nothing until it saves.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

from app.domain.usage import Usage
from app.graph.recorder import AttemptRecord, DecisionRecord, RunCancelled
from app.graph.usage import usage_from_attempts
from app.reasoners.give_up import GaveUp

BeforeReasonHook = Callable[[int, int], None]


def _copy_decision(record: DecisionRecord) -> DecisionRecord:
    out = copy.copy(record)
    out.failure_log = list(record.failure_log)
    out.loads_before = list(record.loads_before)
    out.loads_after = list(record.loads_after)
    return out


class MemoryRecorder:
    def __init__(self, *, before_reason_hook: BeforeReasonHook | None = None) -> None:
        self._attempts: dict[tuple[int, int], AttemptRecord] = {}
        self._decisions: dict[int, DecisionRecord] = {}
        self._cancelled = False
        self._hook = before_reason_hook
        self.attempt_saves = 0
        self.decision_saves = 0
        self.gave_up: GaveUp | None = None  # when the run stopped asking its model

    def cancel(self) -> None:
        self._cancelled = True

    def check_cancelled(self) -> None:
        if self._cancelled:
            raise RunCancelled("the run was cancelled")

    def before_reason(self, task_index: int, attempt: int) -> None:
        if self._hook is not None:
            self._hook(task_index, attempt)

    def save_attempt(self, record: AttemptRecord) -> None:
        self.attempt_saves += 1
        self._attempts[(record.task_index, record.attempt)] = record.copy()

    def attempt(self, task_index: int, attempt: int) -> AttemptRecord | None:
        record = self._attempts.get((task_index, attempt))
        return record.copy() if record is not None else None

    def attempts(self, task_index: int | None = None) -> list[AttemptRecord]:
        """Every recorded attempt (of one task, or all), in (task, attempt) order."""
        keys = sorted(k for k in self._attempts if task_index is None or k[0] == task_index)
        return [self._attempts[k].copy() for k in keys]

    def save_decision(self, record: DecisionRecord) -> None:
        self.decision_saves += 1
        self._decisions[record.task_index] = _copy_decision(record)

    def decisions(self) -> list[DecisionRecord]:
        return [_copy_decision(self._decisions[t]) for t in sorted(self._decisions)]

    def usage(self) -> Usage:
        return usage_from_attempts(self._attempts.values())

    def model_gave_up(self, gave_up: GaveUp) -> None:
        if self.gave_up is None:
            self.gave_up = gave_up

    def assignment(self) -> list[int]:
        return [d.robot for d in self.decisions()]
