"""Where the graph's side effects go. Graph state stays O(robots); everything that grows
with the run (prompts, replies, attempts, decisions) is written through a Recorder.

Every method must be idempotent: LangGraph re-runs the node that was executing at a
crash from its top, so the same record may be saved twice (upsert by its keys).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any, Protocol

from app.domain.usage import Usage
from app.reasoners.base import ReasonerReply
from app.reasoners.give_up import GaveUp


class RunCancelled(Exception):
    """Raised from a node when the run was cancelled; the run service marks it cancelled."""


@dataclass
class AttemptRecord:
    """One prompt -> reply -> validation cycle. Key: (task_index, attempt)."""

    task_index: int
    attempt: int  # 1-based
    tier: int  # 0 first try, 1-3 retry tiers
    system_prompt: str
    user_prompt: str
    reply: ReasonerReply | None = None
    parsed: dict[str, Any] | None = None
    scores: dict[str, float] = field(default_factory=dict)
    quality: float | None = None
    accepted: bool | None = None
    hard_invalid: str | None = None  # why Q was forced to 0, if it was
    feedback: str | None = None

    def copy(self) -> AttemptRecord:
        """Independent of the original where nodes mutate; strings and the frozen reply
        are shared (a full deepcopy was a tenth of a durable run's time)."""
        out = copy.copy(self)
        out.scores = dict(self.scores)
        out.parsed = _copy_json(self.parsed) if self.parsed is not None else None
        return out


def _copy_json(value: Any) -> Any:
    """A deep copy of JSON-shaped data (what `parsed` holds), a few times quicker than
    copy.deepcopy, which a run paid seven times per task."""
    if isinstance(value, dict):
        return {k: _copy_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_copy_json(v) for v in value]
    if isinstance(value, str | int | float | bool | None):
        return value
    return copy.deepcopy(value)


# A decision has four shapes, each for its reader: this record (what the graph produces;
# the graph may not import the store), the Decision row (app.store.models: what the store
# keeps, with its chain hash and flattened time columns), DecisionOut (the supervisors'
# trace, with attempts and attribution) and RunAssignment (a client's page of a run, with
# execution reports); both answers resolve indices to names, read with from_attributes
# (app.runs.endpoints; the mapping to columns: app.runs.records).
@dataclass
class DecisionRecord:
    """The finalised decision for one task. Key: task_index (one per run and task)."""

    task_index: int
    task_id: int | str
    task_name: str
    robot: int
    robot_name: str
    phase: str
    expected_success: float  # true S of the chosen robot
    reasoning: str
    confidence: str
    tradeoff: str
    quality: float
    fallback: bool
    attempts: int
    failure_log: list[str]
    loads_before: list[int]
    loads_after: list[int]
    balance_before: float
    balance_after: float
    severity_after: str
    regret: float | None = None
    # The supervisor's review, when the run's policy sent this decision to one
    # (docs/reviews.md#resolving-a-review).
    review: dict[str, Any] | None = None
    # docs/schedules.md#what-a-decision-records, a timed run: minutes from the plan's start, the
    # task's zone, the minutes travelled just before it, its place in the decision order (the
    # graph's decisions before it) and the trade-off in minutes (how much later it ends than the
    # earliest end an allowed robot offered). None on an untimed run.
    start: float | None = None
    end: float | None = None
    zone: str | None = None
    travel: float | None = None
    seq: int | None = None
    later_by: float | None = None
    # docs/allocation.md#teams, a team task: one {"robot", "feature"} per unit, in unit order
    # (`robot` above is the first). None for a single-robot task.
    team: list[dict[str, str]] | None = None


class Recorder(Protocol):
    def check_cancelled(self) -> None:
        """Raise RunCancelled if the run has been cancelled (called at the top of every node)."""

    def before_reason(self, task_index: int, attempt: int) -> None:
        """Hook before a reasoner call (progress reporting; a test-only pause point)."""

    def save_attempt(self, record: AttemptRecord) -> None: ...

    def attempt(self, task_index: int, attempt: int) -> AttemptRecord | None: ...

    def save_decision(self, record: DecisionRecord) -> None: ...

    def decisions(self) -> list[DecisionRecord]:
        """All finalised decisions, in task order."""

    def usage(self) -> Usage:
        """What the run's recorded LLM calls used (app.domain.usage's rule)."""

    def model_gave_up(self, gave_up: GaveUp) -> None:
        """The run stopped asking its model (docs/reasoners.md#bounded-cost): recorded once,
        however often it is told (every later attempt tells it, and a resumed run again)."""
