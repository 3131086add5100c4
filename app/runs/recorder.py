"""The durable Recorder: the graph's side effects written to the app tables."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any, NoReturn

from sqlalchemy import Connection
from sqlalchemy.orm import Session, sessionmaker

from app.domain.lifecycle import EventKind
from app.domain.usage import Usage
from app.graph.recorder import AttemptRecord, DecisionRecord, RunCancelled
from app.observability.logs import bind
from app.reasoners.attribution import REASONER, RULES
from app.reasoners.base import Reasoner
from app.reasoners.budget import BudgetExhausted, TokenBudgetReasoner
from app.reasoners.give_up import GaveUp
from app.runs import lifecycle, records
from app.store import chain, fenced, leases
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import engine_of, transaction
from app.store.fenced import WriteGuard, Written

log = logging.getLogger("ltaa.runs")


class LeaseLost(RunCancelled):
    """Another process took this run (our lease expired): stop without writing anything."""


class RunSuperseded(RunCancelled):
    """A revision replaced this run (docs/living-plans.md#the-parent): stop without writing anything
    more."""


class RunStop:
    """Why a run should stop at the next node boundary: a cancel, the process draining,
    (scale-out) the run's lease passing to another process, or a revision replacing it."""

    def __init__(self) -> None:
        self.cancelled = threading.Event()
        self.shutting_down = threading.Event()
        self.lease_lost = threading.Event()
        self.superseded = threading.Event()

    def requested(self) -> bool:
        return (
            self.cancelled.is_set()
            or self.shutting_down.is_set()
            or self.lease_lost.is_set()
            or self.superseded.is_set()
        )


class Fence:
    """What every write of a run must find true in its own transaction: the run is still
    `running` (the status fence: a revision supersedes the parent in one transaction that
    writes its row first, so a racing write commits before it, and is pinned, or rolls
    back) and, in scale-out, this process still holds its lease (the lease fence).

    The recorder's writes carry the fence inside their one statement (app.store.fenced);
    calling the fence runs it as statements of its own, for the rare writes that are not
    a fenced upsert (an event)."""

    def __init__(self, guard: WriteGuard, stop: RunStop) -> None:
        self.guard = guard
        self.stop = stop

    def __call__(self, session: Session) -> None:
        run_id = self.guard.run_id
        if self.guard.lease_owner is not None:
            # The lease first: a process that lost the run to another is told so before
            # the state check, which also fails once the new owner moved the run.
            alive = leases.renew(
                session=session,
                owner=self.guard.lease_owner,
                run_ids=[run_id],
                lease_s=self.guard.lease_s,
            )
            if run_id not in alive:
                self._lost("lease")
            if alive[run_id]:
                self.stop.cancelled.set()
        if self.guard.running and not repo.still_running(session=session, run_id=run_id):
            self._lost("status")

    def written(self, connection: Connection, written: Written) -> None:
        """After a fenced write: raise (rolling its transaction back) if the fence refused it;
        note a cancel requested through the lease."""
        if not written.ok:
            self._lost(fenced.why_refused(connection, self.guard))
        if written.cancel_requested:
            self.stop.cancelled.set()

    def _lost(self, which: str) -> NoReturn:
        if which == "lease":
            self.stop.lease_lost.set()
            raise LeaseLost(self.guard.run_id)
        self.stop.superseded.set()
        raise RunSuperseded(self.guard.run_id)


def status_fence(run_id: str, stop: RunStop) -> Fence:
    """The run's writes fenced by its state: status `running`."""
    return Fence(WriteGuard(run_id=run_id, running=True), stop)


def lease_fence(run_id: str, stop: RunStop, *, owner: str, lease_s: float) -> Fence:
    """The run's writes fenced by this process's lease (renewed by each write)."""
    return Fence(WriteGuard(run_id=run_id, running=False, lease_owner=owner, lease_s=lease_s), stop)


def fences(*parts: Fence | None) -> Fence | None:
    """One fence requiring all of the given ones (of one run, and one stop)."""
    given = [f for f in parts if f is not None]
    if not given:
        return None
    if len({f.guard.run_id for f in given}) != 1 or len({id(f.stop) for f in given}) != 1:
        raise ValueError("fences of different runs (or stops) cannot be combined")
    leased = [f.guard for f in given if f.guard.lease_owner is not None]
    guard = WriteGuard(
        run_id=given[0].guard.run_id,
        running=any(f.guard.running for f in given),
        lease_owner=leased[0].lease_owner if leased else None,
        lease_s=leased[0].lease_s if leased else 0.0,
    )
    return Fence(guard, given[0].stop)


def _chain_key(record: DecisionRecord) -> int:
    """Where a decision sits in its run's chain: a timed run's in the order the graph made
    them (docs/schedules.md#the-chain-in-decision-order), others in task order."""
    return record.task_index if record.seq is None else record.seq


class SqlRecorder:
    def __init__(
        self,
        *,
        run_id: str,
        sessions: sessionmaker[Session],
        stop: RunStop,
        fence: Fence | None = None,
        defer_offline: bool = False,
    ) -> None:
        """`defer_offline`: hold the attempts that a re-run would write again identically
        (no reply yet, a reply of the rules reasoner, or an LLM reply already stored) and
        write them in the transaction of their task's decision; False where the graph may
        pause inside a task (a review policy: a resumed `finalize` reads its attempts)."""
        self.run_id = run_id
        self._sessions = sessions
        self._engine = engine_of(sessions)
        self._stop = stop
        self._fence = fence
        # Write-through cache: this process wrote these rows, so reads need no query.
        # After a restart the cache starts empty and reads fall through to the table.
        self._attempts: dict[tuple[int, int], AttemptRecord] = {}
        # Tasks after the last one with a stored attempt (read once, at the first miss)
        # have only the attempts this recorder wrote: one writer per run (the lease fence
        # stops this one if another process takes the run), so a miss there needs no query.
        self._stored_through: int | None = None
        # (chain key, chain hash) of the last decision this recorder wrote: the next
        # decision's link hangs off it, with no read.
        self._tip: tuple[int, str] | None = None
        # Why attempts may wait for their decision: a task killed before its decision is
        # decided again from its start (the checkpoint is taken where a task begins), so an
        # attempt that the re-run writes again identically need not be written before.
        # Three writes a task fewer for a `rules` run. Replies that cost (or failed) are
        # written the moment they arrive, so none is paid twice.
        self._defer = defer_offline
        self._pending: dict[tuple[int, int], dict[str, Any]] = {}
        self._replied: set[tuple[int, int]] = set()  # attempts stored with their reply
        self._gave_up = False  # the run's llm_gave_up event is known to be written

    def check_cancelled(self) -> None:
        if self._stop.lease_lost.is_set():
            raise LeaseLost(self.run_id)
        if self._stop.superseded.is_set():
            raise RunSuperseded(self.run_id)
        if self._stop.requested():
            raise RunCancelled(self.run_id)

    def before_reason(self, task_index: int, attempt: int) -> None:
        # Reasoner (and SDK) logs during this node's call name the run and task.
        bind(run_id=self.run_id, task_index=task_index)

    def _fenced(
        self, connection: Connection, write: Callable[[Connection, WriteGuard | None], Written]
    ) -> None:
        """One statement that carries the fence; raises (rolling its transaction back) if
        the fence refused it."""
        guard = self._fence.guard if self._fence is not None else None
        written = write(connection, guard)
        if self._fence is not None:
            self._fence.written(connection, written)

    def _attempt_write(
        self, values: dict[str, Any]
    ) -> Callable[[Connection, WriteGuard | None], Written]:
        return lambda connection, guard: decision_repo.write_attempt(
            connection=connection, run_id=self.run_id, values=values, guard=guard
        )

    def _reproducible(self, record: AttemptRecord) -> bool:
        """Would a re-run of the task write this attempt again, with nothing paid?"""
        reply = record.reply
        if reply is None or (record.task_index, record.attempt) in self._replied:
            return True
        return reply.extra.get(REASONER) == RULES and "error" not in reply.extra

    def _take_pending(self) -> list[dict[str, Any]]:
        pending = [self._pending[key] for key in sorted(self._pending)]
        self._pending.clear()
        return pending

    def save_attempt(self, record: AttemptRecord) -> None:
        key = (record.task_index, record.attempt)
        values = records.attempt_values(record)
        if self._defer and self._reproducible(record):
            self._pending[key] = values
        else:
            self._pending.pop(key, None)
            with self._engine.begin() as connection:
                for held in self._take_pending():
                    self._fenced(connection, self._attempt_write(held))
                self._fenced(connection, self._attempt_write(values))
            if record.reply is not None:
                self._replied.add(key)
        self._attempts[key] = record.copy()
        # Only the current task's attempts are ever read back.
        for old in [k for k in self._attempts if k[0] < record.task_index]:
            del self._attempts[old]
        self._replied = {k for k in self._replied if k[0] >= record.task_index}

    def _stored_through_task(self) -> int:
        if self._stored_through is None:
            with self._sessions() as session:
                self._stored_through = decision_repo.last_attempted_task(
                    session=session, run_id=self.run_id
                )
        return self._stored_through

    def attempt(self, task_index: int, attempt: int) -> AttemptRecord | None:
        cached = self._attempts.get((task_index, attempt))
        if cached is not None:
            return cached.copy()
        if task_index > self._stored_through_task():
            return None
        with self._sessions() as session:
            row = decision_repo.get_attempt(
                session=session, run_id=self.run_id, task_index=task_index, attempt=attempt
            )
            return records.attempt_record(row) if row is not None else None

    def _chain_hash(self, record: DecisionRecord, values: dict[str, Any]) -> str | None:
        """The decision's link, from what this recorder wrote when it wrote the previous
        decision and every attempt of this task (the table holds nothing else: one writer
        per run); None: to be read from the table once the attempts are in, as after a
        restart."""
        t = record.task_index
        cached = [self._attempts.get((t, k)) for k in range(1, record.attempts + 1)]
        if (
            self._tip is not None
            and self._tip[0] < _chain_key(record)
            and t > self._stored_through_task()
            and sum(1 for key in self._attempts if key[0] == t) == len(cached)
            and all(a is not None for a in cached)
        ):
            digest = chain.attempts_digest(records.attempt_values(a) for a in cached if a)
            return chain.decision_link(self._tip[1], values, digest)
        return None

    def save_decision(self, record: DecisionRecord) -> None:
        """The decision, with the attempts held for it, in one transaction."""
        values = records.decision_values(record)
        computed = self._chain_hash(record, values)
        with self._engine.begin() as connection:
            for held in self._take_pending():
                self._fenced(connection, self._attempt_write(held))
            if computed is None:
                # Read in this transaction: it sees the attempts just written.
                with Session(bind=connection) as session:
                    link = decision_repo.decision_chain_hash(
                        session=session, run_id=self.run_id, values=values
                    )
            else:
                link = computed
            self._fenced(
                connection,
                lambda connection, guard: decision_repo.write_decision(
                    connection=connection,
                    run_id=self.run_id,
                    values=values,
                    chain_hash=link,
                    guard=guard,
                ),
            )
        self._tip = (_chain_key(record), link)
        log.log(
            logging.WARNING if record.fallback else logging.INFO,
            "task %d -> %s (Q %.2f, %d attempt(s)%s)",
            record.task_index,
            record.robot_name,
            record.quality,
            record.attempts,
            ", rules fallback" if record.fallback else "",
            extra={"run_id": self.run_id, "task_index": record.task_index},
        )

    def decisions(self) -> list[DecisionRecord]:
        with self._sessions() as session:
            return [
                records.decision_record(row)
                for row in decision_repo.decisions(session=session, run_id=self.run_id)
            ]

    def usage(self) -> Usage:
        with self._sessions() as session:
            return records.usage_of(decision_repo.reply_costs(session=session, run_id=self.run_id))

    def model_gave_up(self, gave_up: GaveUp) -> None:
        if self._gave_up:
            return
        if record_once(
            self._sessions, self._fence, self.run_id, EventKind.LLM_GAVE_UP, gave_up.as_dict()
        ):
            log.warning(
                "the model failed %d tasks in a row: the rules reasoner decides from task "
                "index %d on",
                gave_up.failing,
                gave_up.task_index,
                extra={"run_id": self.run_id},
            )
        self._gave_up = True


def record_once(
    sessions: sessionmaker[Session],
    fence: Callable[[Session], None] | None,
    run_id: str,
    kind: EventKind,
    detail: dict[str, Any],
) -> bool:
    """Write a run event that a run tells once but may be told again after a restart (the
    token budget spent, the model given up); False when it was written before. `fence`:
    the run's write check (a process that lost the run writes no event either)."""
    with transaction(sessions) as session:
        if fence is not None:
            fence(session)
        if repo.has_event(session=session, run_id=run_id, kind=kind.value):
            return False
        lifecycle.record_event(session, run_id=run_id, kind=kind, detail=detail)
    return True


# -- the token budget -------------------------------------------------------------------------
# A run's token budget wired to its record (the rule itself: app.reasoners.budget).
#
# The tokens spent so far are read from the stored attempts at every (re)start, and the
# switch is written once as a `budget_exhausted` run event, so a run restarted after a
# crash switches at the same task and its trace tells the switch once.


def with_token_budget(
    reasoner: Reasoner,
    *,
    run_id: str,
    budget: int | None,
    sessions: sessionmaker[Session],
    fence: Callable[[Session], None] | None = None,
) -> Reasoner:
    """`reasoner` limited to `budget` tokens for the run; unchanged without a budget.
    `fence` is the recorder's write check (PostgreSQL scale-out): a process that lost the
    run's lease writes no event either."""
    if budget is None:
        return reasoner
    with sessions() as session:
        spent = decision_repo.tokens_spent(session=session, run_id=run_id)

    def record(exhausted: BudgetExhausted) -> None:
        # A run restarted after the switch is told again: the event stays single.
        if not record_once(
            sessions, fence, run_id, EventKind.BUDGET_EXHAUSTED, exhausted.as_dict()
        ):
            return
        log.warning(
            "token budget spent (%d of %d tokens): the rules reasoner decides from "
            "task index %d on",
            exhausted.tokens_spent,
            exhausted.budget,
            exhausted.task_index,
            extra={"run_id": run_id},
        )

    return TokenBudgetReasoner(reasoner, budget=budget, spent=spent, on_exhausted=record)
