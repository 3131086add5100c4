"""A run's life: its statuses, the events of its record, and which moves are allowed.

Pure vocabulary and rules; `app.runs.lifecycle` is the only code that applies them to the
database. A new status (issues to come: `awaiting_review`, `blocked`) is a
member here, a row in `STATUS_RULES` and its rows in `TRANSITIONS`; nothing else needs
hunting down.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class RunStatus(StrEnum):
    QUEUED = "queued"
    RUNNING = "running"
    INTERRUPTED = "interrupted"
    COMPLETED = "completed"
    FAILED = "failed"
    CANCELLED = "cancelled"
    # Its checkpoint belongs to another graph version: no worker takes it up until a
    # supervisor resumes it under a release of that version (or revises it).
    BLOCKED = "blocked"
    # Paused before a decision that its review policy sends to a supervisor
    # (docs/reviews.md#which-decisions-wait-for-review).
    AWAITING_REVIEW = "awaiting_review"
    # Replaced by a revision before it finished (docs/living-plans.md#the-parent): terminal, never
    # claimed again.
    SUPERSEDED = "superseded"


class EventKind(StrEnum):
    """The kinds of row in a run's event record (and its hash chain)."""

    CREATED = "created"
    STARTED = "started"
    RESUMED = "resumed"
    INTERRUPTED = "interrupted"
    COMPLETED = "completed"
    FAILED = "failed"
    CANCELLED = "cancelled"
    INTEGRITY_FAILED = "integrity_failed"
    BUDGET_EXHAUSTED = "budget_exhausted"
    # docs/reasoners.md#bounded-cost: the model failed too many tasks in a row; the rule decides
    # the rest of the run.
    LLM_GAVE_UP = "llm_gave_up"
    UPGRADE_BLOCKED = "upgrade_blocked"
    REVIEW_REQUESTED = "review_requested"
    REVIEW_RESOLVED = "review_resolved"
    REVIEW_CLOSED = "review_closed"
    # docs/living-plans.md#audit: a revision's first event, and its unfinished parent's last.
    REVISED = "revised"
    SUPERSEDED = "superseded"
    # Execution reports while the run is unfinished (after completion: annotations).
    EXECUTION_REPORTED = "execution_reported"
    # docs/schedules.md#guidance-in-time: a guided timed run's guidance plan, written once before
    # its first decision and read back on resume (app.solvers.timed_guidance says why).
    GUIDANCE_PLANNED = "guidance_planned"


@dataclass(frozen=True)
class StatusRule:
    finished: bool  # stamps finished_at: the run ended (failed runs may still be resumed)
    claimable: bool  # a worker may pick the run up on its own (queued or to auto-resume)
    active: bool  # a worker is, or is about to be, executing it


STATUS_RULES: dict[RunStatus, StatusRule] = {
    RunStatus.QUEUED: StatusRule(finished=False, claimable=True, active=True),
    RunStatus.RUNNING: StatusRule(finished=False, claimable=False, active=True),
    RunStatus.INTERRUPTED: StatusRule(finished=False, claimable=True, active=False),
    RunStatus.COMPLETED: StatusRule(finished=True, claimable=False, active=False),
    RunStatus.FAILED: StatusRule(finished=True, claimable=False, active=False),
    RunStatus.CANCELLED: StatusRule(finished=True, claimable=False, active=False),
    RunStatus.BLOCKED: StatusRule(finished=False, claimable=False, active=False),
    # Nobody holds or claims it: it waits for a resolution, which queues it again.
    RunStatus.AWAITING_REVIEW: StatusRule(finished=False, claimable=False, active=False),
    RunStatus.SUPERSEDED: StatusRule(finished=True, claimable=False, active=False),
}

FINISHED: frozenset[RunStatus] = frozenset(s for s, r in STATUS_RULES.items() if r.finished)
CLAIMABLE: frozenset[RunStatus] = frozenset(s for s, r in STATUS_RULES.items() if r.claimable)
ACTIVE: frozenset[RunStatus] = frozenset(s for s, r in STATUS_RULES.items() if r.active)

# (from, to): why the move happens. Anything not listed is refused.
TRANSITIONS: dict[tuple[RunStatus, RunStatus], str] = {
    (RunStatus.QUEUED, RunStatus.RUNNING): "a worker starts it",
    (RunStatus.QUEUED, RunStatus.CANCELLED): "cancelled before it ran",
    (RunStatus.QUEUED, RunStatus.FAILED): "refused before it ran (integrity check)",
    (RunStatus.RUNNING, RunStatus.COMPLETED): "every task decided",
    (RunStatus.RUNNING, RunStatus.FAILED): "the run could not go on",
    (RunStatus.RUNNING, RunStatus.CANCELLED): "cancelled while running",
    (RunStatus.RUNNING, RunStatus.INTERRUPTED): "its process drained, died or lost the lease",
    (RunStatus.INTERRUPTED, RunStatus.RUNNING): "a worker resumes it",
    (RunStatus.INTERRUPTED, RunStatus.QUEUED): "handed to whichever process is free first",
    (RunStatus.INTERRUPTED, RunStatus.CANCELLED): "cancelled while interrupted",
    (RunStatus.INTERRUPTED, RunStatus.FAILED): "refused on resume (integrity check, settings)",
    (RunStatus.FAILED, RunStatus.INTERRUPTED): "a supervisor asked to resume it",
    (RunStatus.INTERRUPTED, RunStatus.BLOCKED): "its checkpoint is of another graph version",
    (RunStatus.QUEUED, RunStatus.BLOCKED): "its checkpoint is of another graph version",
    (RunStatus.BLOCKED, RunStatus.INTERRUPTED): "a supervisor asked to resume it",
    (RunStatus.BLOCKED, RunStatus.CANCELLED): "cancelled while blocked",
    (RunStatus.RUNNING, RunStatus.AWAITING_REVIEW): "a decision needs a supervisor's review",
    (RunStatus.AWAITING_REVIEW, RunStatus.QUEUED): "the review was resolved",
    (RunStatus.AWAITING_REVIEW, RunStatus.CANCELLED): "cancelled while awaiting review",
    (RunStatus.QUEUED, RunStatus.SUPERSEDED): "revised before it ran",
    (RunStatus.RUNNING, RunStatus.SUPERSEDED): "revised while running (its writes are fenced)",
    (RunStatus.INTERRUPTED, RunStatus.SUPERSEDED): "revised while interrupted",
    (RunStatus.AWAITING_REVIEW, RunStatus.SUPERSEDED): "revised while awaiting review",
}


class IllegalTransitionError(ValueError):
    """A move the table does not allow: a bug in the caller, or a race another writer won."""

    def __init__(self, run_id: str, current: RunStatus, target: RunStatus) -> None:
        allowed = sorted(t.value for (f, t) in TRANSITIONS if f is current)
        super().__init__(
            f"run {run_id!r} cannot move from {current.value} to {target.value}; from "
            f"{current.value} it may move to: {', '.join(allowed) or 'nothing (final)'}"
        )
        self.run_id = run_id
        self.current = current
        self.target = target


def check_transition(run_id: str, current: RunStatus | str, target: RunStatus | str) -> None:
    """Raise IllegalTransitionError unless `current -> target` is in the table."""
    now, to = RunStatus(current), RunStatus(target)
    if (now, to) not in TRANSITIONS:
        raise IllegalTransitionError(run_id, now, to)
