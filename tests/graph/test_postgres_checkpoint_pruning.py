"""The PostgreSQL saver prunes a running thread to its latest checkpoint on the same
schedule as the SQLite one, and the thread still resumes exactly once."""

from __future__ import annotations

from typing import Any

import psycopg
import pytest

from app.graph.checkpoint.postgres import PrunedPostgresSaver, libpq_url, open_postgres_saver
from tests.graph.test_checkpoint_pruning import CONFIG, STEPS, Crash, _graph
from tests.support.postgres import fresh_database


def _checkpoints(url: str) -> int:
    with psycopg.connect(libpq_url(url)) as conn:
        row = conn.execute("SELECT count(*) FROM checkpoints").fetchone()
        assert row is not None
        return int(row[0])


def test_postgres_threads_are_pruned_as_they_run_and_resume() -> None:
    with fresh_database() as url:
        saver, close = open_postgres_saver(url, max_connections=2)
        assert isinstance(saver, PrunedPostgresSaver)
        try:
            graph: Any = _graph(saver, crash_at=77)
            with pytest.raises(Crash):
                graph.invoke({"n": 0, "seen": []}, CONFIG, durability="sync")
            assert _checkpoints(url) < 77
            result = _graph(saver, crash_at=None).invoke(None, CONFIG, durability="sync")
            assert result["seen"] == list(range(STEPS))
            assert _checkpoints(url) < 20
        finally:
            close()
