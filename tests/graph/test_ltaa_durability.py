"""Resume with a real SqliteSaver: same allocation, one decision per task, no paid call twice."""

from __future__ import annotations

import sqlite3
from collections.abc import Callable
from pathlib import Path

import pytest
from langgraph.checkpoint.sqlite import SqliteSaver

from app.graph.builder import build_graph
from app.graph.checkpoint import CompactSqliteSaver, open_sqlite_saver
from app.graph.memory_recorder import MemoryRecorder
from app.graph.recorder import AttemptRecord
from app.graph.runner import run_graph
from app.graph.state import GraphContext
from tests.fakes.scripted_reasoner import ScriptedReasoner
from tests.support.ltaa_support import problem, run

PROBLEM = problem()


class Crash(Exception):
    """Stands in for kill -9: raised mid-node, it escapes the graph like a dying process."""


def saver(path: Path, cls: type[SqliteSaver] = SqliteSaver) -> SqliteSaver:
    s = cls(sqlite3.connect(path, check_same_thread=False))
    s.setup()
    # An in-process "crash" loses nothing either way; skipping fsync keeps the test fast.
    s.conn.execute("PRAGMA synchronous=NORMAL")
    return s


def reference() -> list[int]:
    rec, _ = run(PROBLEM)
    return [d.robot for d in rec.decisions()]


def crash_once(at_task: int) -> Callable[[int, int], None]:
    fired: list[int] = []

    def hook(task_index: int, attempt: int) -> None:
        if task_index == at_task and not fired:
            fired.append(task_index)
            raise Crash(f"injected crash while reasoning about task {task_index}")

    return hook


def resume_run(
    path: Path,
    rec: MemoryRecorder,
    reasoner: ScriptedReasoner,
    cls: type[SqliteSaver] = SqliteSaver,
) -> None:
    ctx = GraphContext(problem=PROBLEM, reasoner=reasoner, recorder=rec)
    first = saver(path, cls)
    with pytest.raises(Crash):
        run_graph(build_graph(first), ctx, "run-1", resume=False)
    first.conn.close()
    # A "restarted process": new connection, new compiled graph, same app records.
    second = saver(path, cls)
    final = run_graph(build_graph(second), ctx, "run-1", resume=True)
    assert final["done"] and final["task_index"] == 36
    second.conn.close()


def test_resume_after_a_crash_matches_an_uninterrupted_run(tmp_path: Path) -> None:
    rec = MemoryRecorder(before_reason_hook=crash_once(18))
    reasoner = ScriptedReasoner(model=None)
    resume_run(tmp_path / "cp.sqlite", rec, reasoner)
    decisions = rec.decisions()
    assert [d.task_index for d in decisions] == list(range(36))
    assert [d.robot for d in decisions] == reference()
    assert rec.decision_saves == 36  # nothing stored twice
    assert len(reasoner.calls) == 36  # the crash came before the call for task 18


class CrashAfterReplySaved(MemoryRecorder):
    """Dies right after the reply for one task is stored: the worst moment to lose money."""

    def __init__(self, at_task: int) -> None:
        super().__init__()
        self.at_task, self.fired = at_task, False

    def save_attempt(self, record: AttemptRecord) -> None:
        super().save_attempt(record)
        if record.task_index == self.at_task and record.reply is not None and not self.fired:
            self.fired = True
            raise Crash("injected crash after the reply was saved")


def test_a_recorded_reply_is_reused_not_paid_twice(tmp_path: Path) -> None:
    rec = CrashAfterReplySaved(at_task=10)
    reasoner = ScriptedReasoner()
    resume_run(tmp_path / "cp.sqlite", rec, reasoner)
    assert len(reasoner.calls) == 36
    assert [d.robot for d in rec.decisions()] == reference()


def test_compact_saver_resumes_and_shrinks_checkpoints(tmp_path: Path) -> None:
    rec = MemoryRecorder(before_reason_hook=crash_once(20))
    resume_run(tmp_path / "compact.sqlite", rec, ScriptedReasoner(), CompactSqliteSaver)
    assert [d.robot for d in rec.decisions()] == reference()
    stock = saver(tmp_path / "stock.sqlite")
    compact = open_sqlite_saver(tmp_path / "c2.sqlite", synchronous="NORMAL")
    for s in (stock, compact):
        ctx = GraphContext(problem=PROBLEM, reasoner=ScriptedReasoner(), recorder=MemoryRecorder())
        run_graph(build_graph(s), ctx, "size", resume=False)
    size = {
        name: s.conn.execute("select sum(length(checkpoint)) from checkpoints").fetchone()[0]
        for name, s in (("stock", stock), ("compact", compact))
    }
    assert size["compact"] < 0.6 * size["stock"]


def test_a_stock_thread_can_be_resumed_by_the_compact_saver(tmp_path: Path) -> None:
    path = tmp_path / "mixed.sqlite"
    rec = MemoryRecorder(before_reason_hook=crash_once(7))
    ctx = GraphContext(problem=PROBLEM, reasoner=ScriptedReasoner(), recorder=rec)
    with pytest.raises(Crash):
        run_graph(build_graph(saver(path)), ctx, "run", resume=False)
    run_graph(build_graph(saver(path, CompactSqliteSaver)), ctx, "run", resume=True)
    assert [d.robot for d in rec.decisions()] == reference()
