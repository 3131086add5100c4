"""An optional, smaller SQLite checkpointer for the LTAA graph.

SqliteSaver stores every channel version as a 50-character string
("000...0121.0.4195519186718633"), twice per channel per checkpoint (channel_versions
and versions_seen). For this graph those strings were ~1.9 KB of a ~2.5 KB checkpoint.
Integer versions (LangGraph's default for savers that do not override them) carry the
same ordering in a few bytes.

A thread keeps the version type it started with: LangGraph derives each new version from
the maximum existing one, so a thread begun by the stock saver stays on strings and can
still be resumed by this one.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any

from langgraph.checkpoint.sqlite import SqliteSaver


class CompactSqliteSaver(SqliteSaver):
    def get_next_version(self, current: Any, channel: None) -> Any:
        if current is None:
            return 1
        if isinstance(current, int):
            return current + 1
        return super().get_next_version(current, channel)


def open_sqlite_saver(
    path: str | Path,
    *,
    compact: bool = True,
    synchronous: str | None = None,
    busy_timeout_s: float = 30.0,
) -> SqliteSaver:
    """A saver over its own connection (check_same_thread=False, as SqliteSaver requires).

    `synchronous="NORMAL"` (WAL) skips the fsync at every commit: a process crash (kill -9)
    still loses nothing committed, a power loss may lose the last steps. setup() leaves
    SQLite's default FULL, which fsyncs twice per super-step.
    """
    conn = sqlite3.connect(str(path), check_same_thread=False, timeout=busy_timeout_s)
    saver: SqliteSaver = CompactSqliteSaver(conn) if compact else SqliteSaver(conn)
    saver.setup()
    if synchronous is not None:
        conn.execute(f"PRAGMA synchronous={synchronous}")
    return saver
