"""Bounded checkpoint storage: a thread keeps only its latest few checkpoints while it runs.

Resume reads the latest checkpoint of a thread and the pending writes stored against it;
nothing in this app forks or replays from an older one, so the rest is dead weight that
grew ~17 KB per task (164 MB at 10,000 tasks) until the run completed.
"""

from __future__ import annotations

import threading
from collections import Counter

from langchain_core.runnables import RunnableConfig
from langgraph.checkpoint.base import (
    BaseCheckpointSaver,
    ChannelVersions,
    Checkpoint,
    CheckpointMetadata,
)

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


class PruningPutMixin(BaseCheckpointSaver[str]):
    """Prunes a thread once its schedule says so, right after the checkpoint that made it
    due is stored; the saver says how it prunes. Listed before the saver in the bases, so
    that super().put is the saver's own."""

    _schedule: PruneSchedule

    def prune_due(self, thread_id: str, checkpoint_ns: str) -> None:
        """Prune the thread's superseded checkpoints, the saver's own way.

        Args:
            thread_id: The thread whose checkpoint was just stored.
            checkpoint_ns: The namespace of that checkpoint.
        """
        raise NotImplementedError

    def put(
        self,
        config: RunnableConfig,
        checkpoint: Checkpoint,
        metadata: CheckpointMetadata,
        new_versions: ChannelVersions,
    ) -> RunnableConfig:
        """Store the checkpoint (the saver's put), then prune the thread if it is due.

        Args:
            config: The config to associate with the checkpoint.
            checkpoint: The checkpoint to save.
            metadata: Additional metadata to save with the checkpoint.
            new_versions: New channel versions as of this write.

        Returns:
            RunnableConfig: The saver's config naming the stored checkpoint.
        """
        saved = super().put(config, checkpoint, metadata, new_versions)
        thread_id = str(config["configurable"]["thread_id"])
        if self._schedule.due(thread_id):
            self.prune_due(thread_id, str(config["configurable"].get("checkpoint_ns", "")))
        return saved
