"""validate's verdict on the attempt it just judged, kept for build_feedback (in memory).

One entry per run, never checkpointed: build_feedback only ever asks about the attempt
validate judged right before it. After a crash or resume the cache is empty and
build_feedback re-derives the verdict with the same pure `judge`, so the result is the same.
"""

from __future__ import annotations

from app.graph.validation import Validation


class VerdictCache:
    def __init__(self) -> None:
        self._key: tuple[int, int] | None = None
        self._verdict: Validation | None = None

    def remember(self, task_index: int, attempt: int, verdict: Validation) -> None:
        self._key, self._verdict = (task_index, attempt), verdict

    def recall(self, task_index: int, attempt: int) -> Validation | None:
        return self._verdict if self._key == (task_index, attempt) else None
