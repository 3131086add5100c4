"""Executes durable runs: one compiled graph, one checkpointer, a bounded pool of threads.

Each run is an app-owned task, not tied to an HTTP request. The LangGraph SQLite
checkpointer (durability "sync") makes the graph resumable; the app tables hold the
record. A run found `running` at start-up belonged to a process that died: it is marked
interrupted and, with auto-resume on, resumed from its last checkpoint.

This is the single-process worker of the embedded SQLite default. Several processes on
one PostgreSQL database use `app.runs.leased.LeasedRunWorker`, which overrides the
hooks marked "scale-out hook" below; `app.runs.factory.make_worker` picks one.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

from langgraph.checkpoint.base import BaseCheckpointSaver
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.domain.errors import DomainError
from app.graph.builder import NODES, build_graph
from app.graph.checkpoint import open_sqlite_saver
from app.graph.pause import NodeHook, PausePoint, pause_hook
from app.graph.recorder import RunCancelled
from app.graph.runner import run_graph
from app.reasoners.base import Reasoner
from app.reasoners.factory import close_reasoner, make_reasoner
from app.runs.integrity import check_integrity
from app.runs.recorder import Fence, RunStop, SqlRecorder
from app.runs.replay import recorded_replies
from app.runs.spec import RunSpec
from app.runs.store_lock import StoreLock
from app.runs.token_budget import with_token_budget
from app.solvers.ltaa import graph_context
from app.store import repository as repo
from app.store.db import transaction
from app.store.models import Run

log = logging.getLogger("ltaa.runs")


class RunWorker:
    def __init__(self, *, settings: Settings, sessions: sessionmaker[Session]) -> None:
        self._settings = settings
        self._sessions = sessions
        self._release_store = self._claim_store()
        try:
            self.checkpointer, self._close_checkpointer = self._open_checkpointer()
        except BaseException:
            self._release_store()
            raise
        self.graph = build_graph(self.checkpointer, node_hook=self._pause_hook())
        self._pool = ThreadPoolExecutor(
            max_workers=settings.max_concurrent_runs, thread_name_prefix="ltaa-run"
        )
        self._lock = threading.Lock()
        self._stops: dict[str, RunStop] = {}
        self._futures: dict[str, Future[None]] = {}
        self._closing = False

    def _claim_store(self) -> Callable[[], None]:
        """Scale-out hook: make this the only process on the embedded store (raises
        StoreInUseError otherwise); returns how to let go."""
        url = make_url(self._settings.db_url)
        database = url.database
        if url.get_backend_name() != "sqlite" or not database or database == ":memory:":
            return lambda: None
        lock = StoreLock(Path(database))
        lock.acquire()
        return lock.release

    def _open_checkpointer(self) -> tuple[BaseCheckpointSaver[Any], Callable[[], None]]:
        """Scale-out hook: the saver and how to close it."""
        path = Path(self._settings.checkpoint_file)
        path.parent.mkdir(parents=True, exist_ok=True)
        # One connection for the process (SqliteSaver serialises on its own lock), a
        # generous busy timeout instead of "database is locked" under load, integer channel
        # versions (half the bytes per checkpoint) and synchronous=NORMAL: in WAL mode a
        # kill -9 loses nothing committed; only an OS crash could lose the last steps.
        saver = open_sqlite_saver(path, compact=True, synchronous="NORMAL")
        return saver, saver.conn.close

    def _pause_hook(self) -> NodeHook | None:
        """Test-only: hold runs at one node of one task (LTAA_TEST_PAUSE_AT_NODE)."""
        task, node = self._settings.test_pause_at_task, self._settings.test_pause_at_node
        if task is None or node is None:
            return None
        return pause_hook(PausePoint.parse(task, node), frozenset(NODES))

    # -- lifecycle ---------------------------------------------------------------------

    def recover(self) -> list[str]:
        """Start-up: mark runs orphaned by a dead process interrupted; resume or restart them."""
        with transaction(self._sessions) as session:
            orphans = repo.runs_with_status(session=session, statuses=["running"])
            for run in orphans:
                repo.set_status(session=session, run=run, status="interrupted")
                repo.add_event(
                    session=session,
                    run_id=run.id,
                    kind="interrupted",
                    detail={"reason": "found running at start-up; the process that ran it stopped"},
                )
            queued = [r.id for r in repo.runs_with_status(session=session, statuses=["queued"])]
            interrupted = [
                r.id for r in repo.runs_with_status(session=session, statuses=["interrupted"])
            ]
        for run_id in queued:
            self.submit(run_id)
        if self._settings.auto_resume:
            for run_id in interrupted:
                self.submit(run_id)
        return interrupted if self._settings.auto_resume else []

    def begin_drain(self) -> int:
        """Take no more runs; running ones stop at their next node boundary and are marked
        interrupted. Returns at once, with how many runs it held; close() waits for them."""
        with self._lock:
            self._closing = True
            for stop in self._stops.values():
                stop.shutting_down.set()
            return len(self._stops)

    @property
    def draining(self) -> bool:
        return self._closing

    def close(self) -> None:
        """Drain, wait for the runs to stop, close the checkpointer. Queued runs stay queued."""
        self.begin_drain()
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._close_checkpointer()
        self._release_store()

    # -- commands ----------------------------------------------------------------------

    def submit(self, run_id: str) -> None:
        self._start(run_id)

    def _start(self, run_id: str) -> bool:
        with self._lock:
            if self._closing or run_id in self._futures:
                return False
            stop = RunStop()
            self._stops[run_id] = stop
            self._futures[run_id] = self._pool.submit(self._execute, run_id, stop)
            return True

    def is_active(self, run_id: str) -> bool:
        with self._lock:
            return run_id in self._futures

    def cancel(self, run_id: str) -> None:
        with self._lock:
            stop = self._stops.get(run_id)
        if stop is not None:
            stop.cancelled.set()

    def wait(self, run_id: str, timeout: float | None = None) -> None:
        with self._lock:
            future = self._futures.get(run_id)
        if future is not None:
            future.result(timeout=timeout)

    # -- execution ---------------------------------------------------------------------

    def _config(self, run_id: str) -> dict[str, Any]:
        return {"configurable": {"thread_id": run_id}}

    def _owned_run(self, session: Session, run_id: str) -> Run | None:
        """Scale-out hook: the run, if this process may write its status."""
        return repo.get_run(session=session, run_id=run_id)

    def _fence(self, run_id: str, stop: RunStop) -> Fence | None:
        """Scale-out hook: a check made inside every recorder write."""
        return None

    def _event_detail(self) -> dict[str, Any]:
        """Scale-out hook: added to started/resumed events (which process ran it)."""
        return {}

    def _execute(self, run_id: str, stop: RunStop) -> None:
        try:
            self._run(run_id, stop)
        except Exception:  # a bug must not kill the worker thread silently
            log.exception("run %s crashed", run_id)
            with transaction(self._sessions) as session:
                run = self._owned_run(session, run_id)
                if run is not None and run.status == "running":
                    repo.set_status(
                        session=session,
                        run=run,
                        status="failed",
                        error="internal error; see the server log",
                    )
                    repo.add_event(
                        session=session,
                        run_id=run_id,
                        kind="failed",
                        detail={"error": "internal error"},
                    )
        finally:
            with self._lock:
                self._futures.pop(run_id, None)
                self._stops.pop(run_id, None)

    def _run(self, run_id: str, stop: RunStop) -> None:
        if stop.shutting_down.is_set():
            return  # draining before it began: it stays queued (or interrupted) for the next start
        checkpoint = self.checkpointer.get_tuple(self._config(run_id))
        with transaction(self._sessions) as session:
            run = self._owned_run(session, run_id)
            if run is None or run.status not in ("queued", "interrupted"):
                return
            if run.cancel_requested:
                stop.cancelled.set()
            spec = RunSpec.from_json(run.request)
            problem = spec.problem
            if checkpoint is not None or run.status == "interrupted":
                stored = [
                    repo.decision_record(d) for d in repo.decisions(session=session, run_id=run_id)
                ]
                values = checkpoint.checkpoint["channel_values"] if checkpoint else None
                report = check_integrity(
                    decisions=stored,
                    n_tasks=problem.instance.n_tasks,
                    n_robots=problem.instance.n_robots,
                    checkpoint=values,
                )
                if not report.ok:
                    # Resuming would build on a record that the checkpoint contradicts, and
                    # its final allocation could not be trusted: stop here, say why.
                    repo.add_event(
                        session=session,
                        run_id=run_id,
                        kind="integrity_failed",
                        detail={"integrity": report.as_dict(), **self._event_detail()},
                    )
                    repo.set_status(
                        session=session,
                        run=run,
                        status="failed",
                        error="not resumed: the integrity check failed ("
                        + "; ".join(report.problems)
                        + "). The stored decisions and the "
                        "checkpoint disagree; inspect GET /runs/{id}/trace and "
                        "/trace/verify, then start a new run.",
                    )
                    return
                run.resumes += 1
                repo.add_event(
                    session=session,
                    run_id=run_id,
                    kind="resumed",
                    detail={
                        "integrity": report.as_dict(),
                        "from_checkpoint": checkpoint is not None,
                        **self._event_detail(),
                    },
                )
            else:
                repo.add_event(
                    session=session,
                    run_id=run_id,
                    kind="started",
                    detail={
                        "reasoner": spec.reasoner,
                        "mode": spec.mode,
                        "tasks": problem.instance.n_tasks,
                        **self._event_detail(),
                    },
                )
            repo.set_status(session=session, run=run, status="running")

        fence = self._fence(run_id, stop)
        recorder = SqlRecorder(
            run_id=run_id,
            sessions=self._sessions,
            stop=stop,
            pause_at_task=None
            if self._settings.test_pause_at_node
            else self._settings.test_pause_at_task,
            fence=fence,
        )
        try:
            reasoner = self._reasoner(run_id, spec, fence)
        except DomainError as exc:
            # The configuration changed since the run was accepted (e.g. the API key was
            # removed before a resume): fail with the reason and the fix, not "internal error".
            self._finish(
                run_id,
                "failed",
                {"error": exc.message, "field": exc.field},
                error=f"cannot resume: {exc.message}",
            )
            return
        context = graph_context(
            problem,
            reasoner=reasoner,
            recorder=recorder,
            quality_threshold=spec.quality_threshold,
            max_retries=spec.max_retries,
            guidance=spec.guidance,
        )
        try:
            run_graph(self.graph, context, run_id, resume=checkpoint is not None)
        except RunCancelled:
            self._finish_stopped(run_id, stop)
            return
        except Exception as exc:
            log.exception("run %s failed", run_id)
            self._finish(
                run_id,
                "failed",
                {"error": f"{type(exc).__name__}: {exc}"},
                error=f"{type(exc).__name__}: {exc}",
            )
            return
        finally:
            close_reasoner(reasoner)  # its HTTP connection pool, for the anthropic one
        stored = recorder.decisions()
        if [d.task_index for d in stored] != list(range(problem.instance.n_tasks)):
            # A graph can end without routing (a raising router, LangGraph #8834):
            # completion is judged by our own record, never by the graph returning.
            self._finish(
                run_id,
                "failed",
                {
                    "error": f"graph ended with {len(stored)} of "
                    f"{problem.instance.n_tasks} decisions stored"
                },
                error="graph ended early",
            )
            return
        self._finish(run_id, "completed", {"decisions": len(stored)})

    def _reasoner(self, run_id: str, spec: RunSpec, fence: Fence | None = None) -> Reasoner:
        """The reasoner a run's graph calls, built afresh at every (re)start."""
        replies = (
            recorded_replies(sessions=self._sessions, run_id=spec.replay_of)
            if spec.replay_of is not None
            else None
        )
        reasoner = make_reasoner(
            spec.reasoner,
            settings=self._settings,
            model=spec.model,
            temperature=spec.temperature,
            replay_of=spec.replay_of,
            replies=replies,
            llm_scope=spec.llm_scope,
            llm_margin=spec.llm_margin,
        )
        return with_token_budget(
            reasoner, run_id=run_id, budget=spec.token_budget, sessions=self._sessions, fence=fence
        )

    def _finish_stopped(self, run_id: str, stop: RunStop) -> None:
        if stop.lease_lost.is_set():
            # Another process owns the run now; its record is no longer ours to write.
            log.warning("run %s stopped here: its lease passed to another process", run_id)
            return
        if stop.cancelled.is_set():
            self._finish(run_id, "cancelled", {"reason": "cancel requested"})
        else:
            self._finish(
                run_id, "interrupted", {"reason": "server shutting down"}, event="interrupted"
            )

    def _finish(
        self,
        run_id: str,
        status: str,
        detail: dict[str, Any],
        *,
        error: str | None = None,
        event: str | None = None,
    ) -> None:
        with transaction(self._sessions) as session:
            run = self._owned_run(session, run_id)
            if run is None:
                return
            repo.set_status(session=session, run=run, status=status, error=error)
            repo.add_event(session=session, run_id=run_id, kind=event or status, detail=detail)
        if status in ("completed", "cancelled"):
            self._prune_checkpoints(run_id)

    def _prune_checkpoints(self, run_id: str) -> None:
        """A run that can never resume needs no checkpoints (~17 KB per task); its record
        lives in the app tables. Deleted after the status commits, so a crash in between
        leaves only garbage, never a run without the checkpoint it would resume from."""
        try:
            self.checkpointer.delete_thread(run_id)
        except Exception:  # storage hygiene must not turn a finished run into an error
            log.exception("could not delete the checkpoints of run %s", run_id)
