"""Bounded checkpoints: a thread keeps its latest few checkpoints while it runs, and a
run interrupted between prunes resumes exactly where it stopped."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any, TypedDict

import pytest
from langgraph.checkpoint.base import BaseCheckpointSaver
from langgraph.graph import END, START, StateGraph

from app.graph.checkpoint import (
    WAL_SIZE_LIMIT,
    CompactSqliteSaver,
    PruneSchedule,
    open_sqlite_saver,
)

STEPS = 120


class Counter(TypedDict):
    n: int
    seen: list[int]


class Crash(Exception):
    pass


def _graph(saver: BaseCheckpointSaver[Any], crash_at: int | None) -> Any:
    def step(state: Counter) -> dict[str, object]:
        if crash_at is not None and state["n"] == crash_at:
            raise Crash
        # The whole history in state makes a lost or repeated step visible.
        return {"n": state["n"] + 1, "seen": [*state["seen"], state["n"]]}

    builder = StateGraph(Counter)
    builder.add_node("step", step)
    builder.add_edge(START, "step")
    builder.add_conditional_edges("step", lambda s: END if s["n"] >= STEPS else "step")
    return builder.compile(checkpointer=saver)


def _rows(path: Path, table: str) -> int:
    with sqlite3.connect(path) as conn:
        return int(conn.execute(f"SELECT count(*) FROM {table}").fetchone()[0])


def _saver(path: Path, **kwargs: int) -> CompactSqliteSaver:
    saver = open_sqlite_saver(path, synchronous="NORMAL")
    assert isinstance(saver, CompactSqliteSaver)
    for name, value in kwargs.items():
        setattr(saver, name, value)
    return saver


CONFIG: Any = {"configurable": {"thread_id": "t"}, "recursion_limit": 1_000}


def test_a_long_thread_keeps_only_its_latest_checkpoints(tmp_path: Path) -> None:
    path = tmp_path / "cp.sqlite"
    saver = _saver(path)
    graph = _graph(saver, crash_at=None)
    result = graph.invoke({"n": 0, "seen": []}, CONFIG, durability="sync")
    assert result["seen"] == list(range(STEPS))
    kept = _rows(path, "checkpoints")
    # Without pruning: one checkpoint per super-step (121 here).
    assert saver.keep_latest <= kept < saver.keep_latest + saver._schedule.every
    latest = saver.get_tuple({"configurable": {"thread_id": "t"}})
    assert latest is not None and latest.checkpoint["channel_values"]["n"] == STEPS
    saver.conn.close()


def test_a_run_interrupted_after_prunes_resumes_exactly_once(tmp_path: Path) -> None:
    path = tmp_path / "cp.sqlite"
    first = _saver(path)
    with pytest.raises(Crash):
        _graph(first, crash_at=77).invoke({"n": 0, "seen": []}, CONFIG, durability="sync")
    first.conn.close()
    assert _rows(path, "checkpoints") < 77  # pruned before the crash

    second = _saver(path)  # a new process: the file alone
    result = _graph(second, crash_at=None).invoke(None, CONFIG, durability="sync")
    assert result["seen"] == list(range(STEPS))  # nothing lost, nothing repeated
    second.conn.close()


def test_the_wal_has_a_size_limit(tmp_path: Path) -> None:
    saver = open_sqlite_saver(tmp_path / "cp.sqlite")
    limit = saver.conn.execute("PRAGMA journal_size_limit").fetchone()[0]
    assert limit == WAL_SIZE_LIMIT
    saver.conn.close()


def test_prune_schedule_counts_per_thread() -> None:
    schedule = PruneSchedule(every=3)
    assert [schedule.due("a") for _ in range(6)] == [False, False, True, False, False, True]
    assert [schedule.due("b") for _ in range(2)] == [False, False]
    with pytest.raises(ValueError):
        PruneSchedule(every=0)
