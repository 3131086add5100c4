"""Bounded checkpoint storage: a thread keeps only its latest few checkpoints while it runs.

Resume reads the latest checkpoint of a thread and the pending writes stored against it;
nothing in this app forks or replays from an older one, so the rest is dead weight that
grew ~17 KB per task (164 MB at 10,000 tasks) until the run completed.
"""

from __future__ import annotations

import threading
from collections import Counter

# Kept per thread and namespace: the latest one is all a resume needs; a few more cost
# little and keep a parent in place for whatever looks one step back.
KEEP_LATEST = 4
# Pruned after this many checkpoints of a thread: one DELETE per few tasks, not per step.
PRUNE_EVERY = 20


class PruneSchedule:
    """Counts checkpoints per thread, thread-safely, and says when one is due a prune."""

    def __init__(self, every: int = PRUNE_EVERY) -> None:
        if every < 1:
            raise ValueError("prune every must be at least 1")
        self.every = every
        self._counts: Counter[str] = Counter()
        self._lock = threading.Lock()

    def due(self, thread_id: str) -> bool:
        with self._lock:
            self._counts[thread_id] += 1
            if self._counts[thread_id] < self.every:
                return False
            del self._counts[thread_id]
            return True
