"""Checkpoints written at task boundaries, not at every super-step.

With durability "sync", LangGraph hands the saver a checkpoint after every super-step (7
per task) and the writes of every node: 14 SQLite commits per task, a third of a durable
run's overhead. Resuming needs far less. Every node's side effects are idempotent and in
the app tables (an LLM reply is recorded before `reason` returns and reused when the node
runs again), so a run resumed from the checkpoint taken when its current task began
decides that task again exactly as an uninterrupted run would: same prompts, the recorded
replies, the same decision, nothing paid twice. So this saver writes a thread's checkpoint
only when

- the next step runs a node of `boundary` (the graph's first node: a task begins), or
- it is the input checkpoint, or the graph's last one (no node to run next),

and keeps the other checkpoints in memory only, the latest per thread: when a node pauses
the graph with `interrupt()` (a review), that checkpoint and the interrupt's writes are
written at once, so the pause survives the process. Other writes (a node's state updates)
are dropped: their step is re-run on resume.

How a checkpoint says which nodes run next is LangGraph's: 1.x keeps a `branch:to:<node>`
channel per triggered node in `channel_values` (see LANGGRAPH-NOTES.md). For savers that
store the whole state per checkpoint (SQLite); the PostgreSQL saver stores per-version
blobs written only with the step that changed them, so skipping steps would lose blobs.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import Any

from langchain_core.runnables import RunnableConfig
from langgraph.checkpoint.base import (
    BaseCheckpointSaver,
    ChannelVersions,
    Checkpoint,
    CheckpointMetadata,
)

BRANCH = "branch:to:"
# Writes that must reach the disk with their checkpoint: a pending interrupt (the graph
# paused for a review) and the value it is resumed with.
KEPT_WRITES = frozenset({"__interrupt__", "__resume__"})

_Pending = tuple[RunnableConfig, Checkpoint, CheckpointMetadata, ChannelVersions]


def next_nodes(checkpoint: Checkpoint) -> set[str]:
    """The nodes the step after this checkpoint runs (LangGraph 1.x's trigger channels)."""
    return {name[len(BRANCH) :] for name in checkpoint["channel_values"] if name.startswith(BRANCH)}


def saved_config(config: RunnableConfig, checkpoint: Checkpoint) -> RunnableConfig:
    """What `put` returns: the config naming the checkpoint just put."""
    configurable = config["configurable"]
    return {
        "configurable": {
            "thread_id": configurable["thread_id"],
            "checkpoint_ns": configurable.get("checkpoint_ns", ""),
            "checkpoint_id": checkpoint["id"],
        }
    }


class TaskBoundaryMixin(BaseCheckpointSaver[Any]):
    """Listed before the saver in the bases, so that super() is the saver's own put."""

    boundary: frozenset[str]

    def _init_boundary(self, boundary: Sequence[str]) -> None:
        if not boundary:
            raise ValueError("name the node(s) a task begins with")
        self.boundary = frozenset(boundary)
        self._unwritten: dict[str, _Pending] = {}
        self._unwritten_lock = threading.Lock()

    def durable(self, checkpoint: Checkpoint, metadata: CheckpointMetadata) -> bool:
        """Whether this checkpoint goes to disk: the input one, the last one, or one whose
        next step begins a task."""
        after = next_nodes(checkpoint)
        return metadata.get("source") == "input" or not after or bool(after & self.boundary)

    def put(
        self,
        config: RunnableConfig,
        checkpoint: Checkpoint,
        metadata: CheckpointMetadata,
        new_versions: ChannelVersions,
    ) -> RunnableConfig:
        """Write the checkpoint if a task begins at it (or it is the input or the last
        one); else keep it in memory as the thread's latest, unwritten.

        Args:
            config: The config to associate with the checkpoint.
            checkpoint: The checkpoint to save.
            metadata: Additional metadata to save with the checkpoint.
            new_versions: New channel versions as of this write.

        Returns:
            RunnableConfig: The config naming the checkpoint, written or not.
        """
        thread_id = str(config["configurable"]["thread_id"])
        if self.durable(checkpoint, metadata):
            with self._unwritten_lock:
                self._unwritten.pop(thread_id, None)
            return super().put(config, checkpoint, metadata, new_versions)
        with self._unwritten_lock:
            self._unwritten[thread_id] = (config, checkpoint, metadata, new_versions)
        return saved_config(config, checkpoint)

    def put_writes(
        self,
        config: RunnableConfig,
        writes: Sequence[tuple[str, Any]],
        task_id: str,
        task_path: str = "",
    ) -> None:
        """Store an interrupt's writes (first writing the checkpoint they belong to, if
        it was kept in memory); drop every other write, whose step re-runs on resume.

        Args:
            config: The config naming the checkpoint the writes belong to.
            writes: (channel, value) pairs.
            task_id: The task that made the writes.
            task_path: The task's path, as the base class takes it.
        """
        if not any(channel in KEPT_WRITES for channel, _ in writes):
            return
        configurable = config["configurable"]
        thread_id = str(configurable["thread_id"])
        with self._unwritten_lock:
            pending = self._unwritten.get(thread_id)
            if pending is not None and pending[1]["id"] == configurable.get("checkpoint_id"):
                del self._unwritten[thread_id]
            else:
                pending = None
        if pending is not None:
            super().put(*pending)  # the checkpoint the interrupt belongs to, first
        super().put_writes(config, writes, task_id, task_path)

    def delete_thread(self, thread_id: str) -> None:
        """Delete the thread's checkpoints and writes, and its unwritten latest.

        Args:
            thread_id: The thread ID to delete.
        """
        with self._unwritten_lock:
            self._unwritten.pop(str(thread_id), None)
        super().delete_thread(thread_id)
