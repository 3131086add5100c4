"""Executes durable runs: one compiled graph, one checkpointer, a bounded pool of threads.

Each run is an app-owned task, not tied to an HTTP request. The LangGraph checkpointer
(durability "sync") makes the graph resumable; the app tables hold the record. Which runs
this process executes is its `Ownership`'s business (app.runs.ownership: the SQLite
process lock, or PostgreSQL leases); app.runs.factory.make_worker composes the two.

A run's execution, in order: admit it (integrity gate, `started`/`resumed`, status
running), build its reasoner, execute the graph (app.solvers.ltaa.execute_ltaa, the one
execution path), then record how it ended.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

from langgraph.checkpoint.base import BaseCheckpointSaver, CheckpointTuple
from sqlalchemy.orm import Session, sessionmaker

from app.audit.signing import SigningKeys, sign_in
from app.config import Settings
from app.domain.errors import DomainError
from app.graph.builder import build_graph
from app.graph.checkpoint import TaskBoundaryMixin
from app.graph.execution import GraphEndedEarly
from app.graph.pause import NodeHook
from app.graph.recorder import RunCancelled
from app.graph.version import compatible, current_version, upgrade_blocked_message
from app.reasoners.base import Reasoner
from app.reasoners.factory import make_reasoner
from app.runs import lifecycle, records, review_gate
from app.runs.integrity import checked_for_resume
from app.runs.lifecycle import EventKind, RunStatus
from app.runs.ownership import Ownership
from app.runs.recorder import Fence, RunStop, SqlRecorder, fences, status_fence, with_token_budget
from app.runs.replay_source import recorded_replies
from app.runs.spec import RunSpec
from app.solvers.ltaa import execute_ltaa, model_use_for
from app.store import repository as repo
from app.store.db import transaction

log = logging.getLogger("ltaa.runs")

# A saver and how to close it.
Checkpointer = tuple[BaseCheckpointSaver[Any], Callable[[], None]]


@dataclass(frozen=True)
class Admission:
    """A run admitted for execution: what it was asked to do, and whether it resumes."""

    spec: RunSpec
    resume: bool
    # A review's resolution to resume the paused graph with (`Command(resume=...)`).
    resume_with: dict[str, Any] | None = None


class RunWorker:
    def __init__(
        self,
        *,
        settings: Settings,
        sessions: sessionmaker[Session],
        ownership: Ownership,
        checkpointer: Checkpointer,
        node_hook: NodeHook | None = None,
    ) -> None:
        self._settings = settings
        self._sessions = sessions
        self.ownership = ownership
        self.checkpointer, self._close_checkpointer = checkpointer
        self.signing_keys = SigningKeys.from_settings(settings)
        self.graph = build_graph(self.checkpointer, node_hook=node_hook)
        # The graph this process runs, read once: every run it admits starts or resumes
        # under it (docs/operations.md#upgrades: a resume compares it with the run's).
        self.graph_version = current_version(settings.test_graph_version)
        self._pool = ThreadPoolExecutor(
            max_workers=settings.max_concurrent_runs, thread_name_prefix="ltaa-run"
        )
        self._lock = threading.Lock()
        self._stops: dict[str, RunStop] = {}
        self._futures: dict[str, Future[None]] = {}
        self._closing = False
        ownership.attach(self)

    # -- lifecycle ---------------------------------------------------------------------

    def recover(self) -> list[str]:
        """Start-up: take up queued and interrupted runs; returns the interrupted ones resumed."""
        return self.ownership.recover()

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
        self.ownership.stop_taking()
        self.begin_drain()
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._close_checkpointer()
        self.ownership.close()

    # -- slots (what the ownership strategy drives) --------------------------------------

    def start(self, run_id: str) -> bool:
        with self._lock:
            if self._closing or run_id in self._futures:
                return False
            stop = RunStop()
            self._stops[run_id] = stop
            self._futures[run_id] = self._pool.submit(self._execute, run_id, stop)
            return True

    def free_slots(self) -> int:
        with self._lock:
            return self._settings.max_concurrent_runs - len(self._futures)

    def held(self) -> dict[str, RunStop]:
        with self._lock:
            return dict(self._stops)

    # -- commands ----------------------------------------------------------------------

    def submit(self, run_id: str) -> None:
        self.ownership.submit(run_id)

    def is_active(self, run_id: str) -> bool:
        with self._lock:
            if run_id in self._futures:
                return True
        return self.ownership.is_active(run_id)

    def cancel(self, run_id: str) -> None:
        with self._lock:
            stop = self._stops.get(run_id)
        if stop is not None:
            stop.cancelled.set()

    def supersede(self, run_id: str) -> None:
        """A revision replaced the run: if this process executes it, stop it writing."""
        with self._lock:
            stop = self._stops.get(run_id)
        if stop is not None:
            stop.superseded.set()

    def wait(self, run_id: str, timeout: float | None = None) -> None:
        with self._lock:
            future = self._futures.get(run_id)
        if future is not None:
            future.result(timeout=timeout)

    # -- execution ---------------------------------------------------------------------

    def _execute(self, run_id: str, stop: RunStop) -> None:
        paused = False
        try:
            paused = self._run(run_id, stop)
        except Exception:  # a bug must not kill the worker thread silently
            log.exception("run %s crashed", run_id)
            self._end(
                run_id,
                RunStatus.FAILED,
                {"error": "internal error"},
                error="internal error; see the server log",
                only_if_running=True,
            )
        finally:
            with self._lock:
                self._futures.pop(run_id, None)
                self._stops.pop(run_id, None)
            self.ownership.finished(run_id, stop)
        if paused:
            # A resolution that came while this thread was still winding down found the
            # run held here (submit refused it): pick it up now that the slot is free.
            with self._sessions() as session:
                run = repo.get_run(session=session, run_id=run_id)
                queued = run is not None and run.status == RunStatus.QUEUED
            if queued:
                self.submit(run_id)

    def _run(self, run_id: str, stop: RunStop) -> bool:
        """Execute the run; True if it paused for a review."""
        if stop.shutting_down.is_set():
            return False  # draining before it began: it stays queued (or interrupted)
        checkpoint = self.checkpointer.get_tuple({"configurable": {"thread_id": run_id}})
        admission = self._admit(run_id, stop, checkpoint)
        if admission is None:
            return False
        spec = admission.spec
        # The lease first: a process that lost the run to another is told so (LeaseLost)
        # before the state check, which also fails once the new owner moved the run.
        fence = fences(self.ownership.fence(run_id, stop), status_fence(run_id, stop))
        # Attempts wait for their decision's transaction only where a resume starts the
        # task again (the SQLite saver checkpoints where a task begins; PostgreSQL's every
        # step, so a resumed node reads the attempts before it) and no review may pause
        # the graph inside a task (a resumed `finalize` reads them from the table).
        recorder = SqlRecorder(
            run_id=run_id,
            sessions=self._sessions,
            stop=stop,
            fence=fence,
            defer_offline=spec.review_policy is None
            and isinstance(self.checkpointer, TaskBoundaryMixin),
        )
        try:
            reasoner = self._reasoner(run_id, spec, fence)
        except DomainError as exc:
            # The configuration changed since the run was accepted (e.g. the API key was
            # removed before a resume): fail with the reason and the fix, not "internal error".
            self._end(
                run_id,
                RunStatus.FAILED,
                {"error": exc.message, "field": exc.field},
                error=f"cannot resume: {exc.message}",
            )
            return False
        recorded = None
        if spec.replay_of is not None:
            # A replay re-applies the original's resolutions and never waits for a review.
            with self._sessions() as session:
                recorded = review_gate.recorded_resolutions(session=session, run_id=spec.replay_of)
        try:
            # A guided timed run's plan, stored once: a resume follows the same one.
            plan = records.guidance_plan(
                self._sessions, run_id, spec.problem, spec.guidance, spec.replay_of
            )
            execution = execute_ltaa(
                spec.problem,
                graph=self.graph,
                thread_id=run_id,
                reasoner=reasoner,
                recorder=recorder,
                quality_threshold=spec.quality_threshold,
                max_retries=spec.max_retries,
                guidance=spec.guidance,
                resume=checkpoint is not None,
                review=spec.review_policy if recorded is None else None,
                recorded_reviews=recorded,
                resume_with=admission.resume_with,
                rate_notes=spec.rate_notes,
                plan=plan,
                model_use=model_use_for(spec.reasoner, spec.reply_format, spec.llm_give_up_after),
            )
        except RunCancelled:
            self._end_stopped(run_id, stop)
        except GraphEndedEarly as exc:
            # Completion is judged by our own record, never by the graph returning.
            self._end(run_id, RunStatus.FAILED, {"error": str(exc)}, error="graph ended early")
        except Exception as exc:
            log.exception("run %s failed", run_id)
            message = f"{type(exc).__name__}: {exc}"
            self._end(run_id, RunStatus.FAILED, {"error": message}, error=message)
        else:
            if execution.paused is not None:
                self._pause(run_id, stop, execution.paused)
                return True
            self._end(run_id, RunStatus.COMPLETED, {"decisions": len(execution.decisions)})
        return False

    def _pause(self, run_id: str, stop: RunStop, payload: dict[str, Any]) -> None:
        """The graph paused for a review: record it and let go of the run (no slot is held
        while it waits; a resolution queues it again)."""
        with transaction(self._sessions) as session:
            run = self.ownership.owned_run(session, run_id)
            if run is None or run.status != RunStatus.RUNNING:
                return
            if stop.cancelled.is_set() or run.cancel_requested:
                lifecycle.move(
                    session,
                    run,
                    RunStatus.CANCELLED,
                    event=EventKind.CANCELLED,
                    detail={"reason": "cancel requested"},
                )
                cancelled = True
            else:
                review_gate.pause_for_review(session, run, payload)
                cancelled = False
        if cancelled:
            self._prune_checkpoints(run_id)
        else:
            log.info(
                "run %s awaits review of task %s (%s)",
                run_id,
                payload.get("task_index"),
                ", ".join(payload.get("triggers", [])),
                extra={"run_id": run_id},
            )

    def _admit(
        self, run_id: str, stop: RunStop, checkpoint: CheckpointTuple | None
    ) -> Admission | None:
        """Move a claimable run to running with its `started` or `resumed` event, after the
        integrity check when it resumes; None if it is not this worker's to run now."""
        detail = self.ownership.event_detail()
        with transaction(self._sessions) as session:
            run = self.ownership.owned_run(session, run_id)
            if run is None or run.status not in (RunStatus.QUEUED, RunStatus.INTERRUPTED):
                return None
            if run.cancel_requested:
                stop.cancelled.set()
            spec = RunSpec.from_json(run.request)
            instance = spec.problem.instance
            resume = checkpoint is not None or run.status == RunStatus.INTERRUPTED
            version = self.graph_version
            resolution = review_gate.resolution_to_apply(session, run_id) if resume else None
            if resolution is not None and run.status == RunStatus.QUEUED:
                # Queued by a review's resolution: the paused graph goes on with it. Not a
                # crash resume, so neither `resumes` nor a `resumed` event.
                lifecycle.move(session, run, RunStatus.RUNNING)
                return Admission(spec=spec, resume=True, resume_with=resolution)
            if not resume:
                run.graph_version = version
                lifecycle.move(
                    session,
                    run,
                    RunStatus.RUNNING,
                    event=EventKind.STARTED,
                    detail={
                        "reasoner": spec.reasoner,
                        "mode": spec.mode,
                        "tasks": instance.n_tasks,
                        "graph_version": version,
                        **detail,
                    },
                )
                return Admission(spec=spec, resume=False)
            if not compatible(run.graph_version, version):
                # Refused before anything runs, and not claimable: no process loops on it.
                started_under = run.graph_version or ""
                lifecycle.move(
                    session,
                    run,
                    RunStatus.BLOCKED,
                    event=EventKind.UPGRADE_BLOCKED,
                    detail={"started_under": started_under, "current": version, **detail},
                    error=upgrade_blocked_message(started_under, version),
                )
                return None
            # A run from before versions were recorded goes on under this one, from now on.
            run.graph_version = version
            report = checked_for_resume(session, run, spec, checkpoint, detail)
            if report is None:
                return None
            run.resumes += 1
            lifecycle.move(
                session,
                run,
                RunStatus.RUNNING,
                event=EventKind.RESUMED,
                detail={
                    "integrity": report.as_dict(),
                    "from_checkpoint": checkpoint is not None,
                    **detail,
                },
            )
            return Admission(spec=spec, resume=True, resume_with=resolution)

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
            reply_format=spec.reply_format,
        )
        return with_token_budget(
            reasoner, run_id=run_id, budget=spec.token_budget, sessions=self._sessions, fence=fence
        )

    def _end_stopped(self, run_id: str, stop: RunStop) -> None:
        if stop.superseded.is_set():
            # The revision's transaction moved it to superseded, with its event.
            log.info("run %s stopped: superseded by a revision", run_id)
            return
        if stop.lease_lost.is_set():
            # Another process owns the run now; its record is no longer ours to write.
            log.warning("run %s stopped here: its lease passed to another process", run_id)
            return
        if stop.cancelled.is_set():
            self._end(run_id, RunStatus.CANCELLED, {"reason": "cancel requested"})
        else:
            self._end(run_id, RunStatus.INTERRUPTED, {"reason": "server shutting down"})

    def _end(
        self,
        run_id: str,
        status: RunStatus,
        detail: dict[str, Any],
        *,
        error: str | None = None,
        only_if_running: bool = False,
    ) -> None:
        """Move the run to how it ended, with the event of the same name."""
        with transaction(self._sessions) as session:
            run = self.ownership.owned_run(session, run_id)
            if run is None or (only_if_running and run.status != RunStatus.RUNNING):
                return
            if run.status == RunStatus.SUPERSEDED:
                # A revision ended it (made through another process, or between two checks).
                log.info("run %s stopped: superseded by a revision", run_id)
                return
            lifecycle.move(
                session, run, status, event=EventKind(status.value), detail=detail, error=error
            )
            if status == RunStatus.COMPLETED:
                # In the transaction that writes the completed event: the heads signed are
                # the final ones, and no reader sees a completed run without its signature.
                sign_in(session, self.signing_keys, run, "completed")
        if status in (RunStatus.COMPLETED, RunStatus.CANCELLED):
            self._prune_checkpoints(run_id)

    def _prune_checkpoints(self, run_id: str) -> None:
        """A run that can never resume needs no checkpoints (~17 KB per task); its record
        lives in the app tables. Deleted after the status commits, so a crash in between
        leaves only garbage, never a run without the checkpoint it would resume from."""
        try:
            self.checkpointer.delete_thread(run_id)
        except Exception:  # storage hygiene must not turn a finished run into an error
            log.exception("could not delete the checkpoints of run %s", run_id)
