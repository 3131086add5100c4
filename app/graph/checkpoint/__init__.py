"""The LTAA graph's checkpoint savers, one package as LangGraph's own
`langgraph.checkpoint.sqlite`: the SQLite savers here, the PostgreSQL one in
`app.graph.checkpoint.postgres` (imported only when the database URL is PostgreSQL, so the
embedded SQLite default never loads psycopg), and what both share in private modules:
pruning a thread's superseded checkpoints as it runs (`_pruning`) and writing checkpoints
only at task boundaries (`_sparse`).

The SQLite savers are smaller than SqliteSaver: it stores every channel version as a
50-character string ("000...0121.0.4195519186718633"), twice per channel per checkpoint
(channel_versions and versions_seen). For this graph those strings were ~1.9 KB of a
~2.5 KB checkpoint. Integer versions (LangGraph's default for savers that do not override
them) carry the same ordering in a few bytes.

A thread keeps the version type it started with: LangGraph derives each new version from
the maximum existing one, so a thread begun by the stock saver stays on strings and can
still be resumed by this one.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from langgraph.checkpoint.sqlite import SqliteSaver

from app.graph.checkpoint._pruning import KEEP_LATEST, PRUNE_EVERY, PruneSchedule, PruningPutMixin
from app.graph.checkpoint._sparse import TaskBoundaryMixin

__all__ = [
    "KEEP_LATEST",
    "PRUNE_EVERY",
    "TRUNCATE_WAL_EVERY",
    "WAL_SIZE_LIMIT",
    "CompactSqliteSaver",
    "PruneSchedule",
    "PruningPutMixin",
    "TaskBoundaryMixin",
    "TaskBoundarySqliteSaver",
    "open_sqlite_saver",
]

# The WAL is truncated back to this after each checkpoint of it; without a limit SQLite
# keeps the file at its high-water mark (169 MB after a 10,000-task run).
WAL_SIZE_LIMIT = 4 * 1024 * 1024
# Every this many prunes the WAL is folded into the file and truncated to zero, in case a
# reader kept the automatic checkpoints from reaching its end.
TRUNCATE_WAL_EVERY = 10

# Older than the keep-th newest checkpoint of (thread, namespace). Checkpoint ids are
# time-ordered (uuid6), which is how SqliteSaver itself finds the latest one.
_OLDER = """
    thread_id = ? AND checkpoint_ns = ? AND checkpoint_id < (
        SELECT checkpoint_id FROM checkpoints WHERE thread_id = ? AND checkpoint_ns = ?
        ORDER BY checkpoint_id DESC LIMIT 1 OFFSET ?
    )
"""


class CompactSqliteSaver(PruningPutMixin, SqliteSaver):
    """Integer channel versions, and a thread's superseded checkpoints pruned as it runs."""

    def __init__(
        self,
        conn: sqlite3.Connection,
        *,
        keep_latest: int = KEEP_LATEST,
        prune_every: int = PRUNE_EVERY,
    ) -> None:
        super().__init__(conn)
        if keep_latest < 1:
            raise ValueError("keep_latest must be at least 1: a resume needs the latest")
        self.keep_latest = keep_latest
        self._schedule = PruneSchedule(prune_every)
        self._prunes = 0

    def get_next_version(self, current: Any, channel: None) -> Any:
        """The next version of a channel: an integer, unless the thread began on strings.

        Args:
            current: The channel's current version (None for a new channel).
            channel: Unused, as in the base class.

        Returns:
            current + 1 for an integer (1 for a new channel); the base class's string
            successor for a thread the stock saver began.
        """
        if current is None:
            return 1
        if isinstance(current, int):
            return current + 1
        return super().get_next_version(current, channel)

    def prune_due(self, thread_id: str, checkpoint_ns: str) -> None:
        """Prune the thread its schedule says is due (PruningPutMixin).

        Args:
            thread_id: The thread (the run id) whose checkpoint was just stored.
            checkpoint_ns: The namespace of that checkpoint.
        """
        self.prune_thread(thread_id, checkpoint_ns)

    def prune_thread(self, thread_id: str, checkpoint_ns: str = "") -> None:
        """Delete the thread's checkpoints older than its latest keep_latest, with their
        writes, in one transaction: a kill -9 leaves either all of them or the pruned set,
        and the latest checkpoint with its pending writes in both."""
        args = (thread_id, checkpoint_ns, thread_id, checkpoint_ns, self.keep_latest - 1)
        with self.cursor() as cur:
            cur.execute(f"DELETE FROM writes WHERE {_OLDER}", args)
            cur.execute(f"DELETE FROM checkpoints WHERE {_OLDER}", args)
        self._prunes += 1
        if self._prunes % TRUNCATE_WAL_EVERY == 0:
            self.truncate_wal()

    def truncate_wal(self) -> None:
        """Fold the WAL into the file and cut it to zero; a busy reader makes it a no-op."""
        with self.cursor(transaction=False) as cur:
            cur.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()


class TaskBoundarySqliteSaver(TaskBoundaryMixin, CompactSqliteSaver):
    """The compact saver, writing a thread's checkpoints only where a task begins (and
    where the graph pauses or ends): app.graph.checkpoint._sparse."""

    def __init__(self, conn: sqlite3.Connection, *, boundary: Sequence[str]) -> None:
        super().__init__(conn)
        self._init_boundary(boundary)


def open_sqlite_saver(
    path: str | Path,
    *,
    compact: bool = True,
    synchronous: str | None = None,
    busy_timeout_s: float = 30.0,
    boundary: Sequence[str] | None = None,
) -> SqliteSaver:
    """A saver over its own connection (check_same_thread=False, as SqliteSaver requires).

    `synchronous="NORMAL"` (WAL) skips the fsync at every commit: a process crash (kill -9)
    still loses nothing committed, a power loss may lose the last steps. setup() leaves
    SQLite's default FULL, which fsyncs twice per super-step.
    `boundary`: the node(s) a task begins with; the saver then writes checkpoints only
    there (TaskBoundarySqliteSaver; implies compact).
    """
    conn = sqlite3.connect(str(path), check_same_thread=False, timeout=busy_timeout_s)
    saver: SqliteSaver
    if boundary is not None:
        saver = TaskBoundarySqliteSaver(conn, boundary=boundary)
    else:
        saver = CompactSqliteSaver(conn) if compact else SqliteSaver(conn)
    saver.setup()
    conn.execute(f"PRAGMA journal_size_limit={WAL_SIZE_LIMIT}")
    if synchronous is not None:
        conn.execute(f"PRAGMA synchronous={synchronous}")
    return saver
