"""Time in a revision (docs/living-plans.md#a-revision-in-time), computed from the revision's queue
without touching the database.

- `now` (default: the request's arrival) is the revision's minute `not_before`: nothing
  that has not started is planned earlier. An explicit `now` before the plan's start is a
  422; an arrival before it plans from minute 0.
- A pinned task the site reported started or done is a fact at its reported times: its
  start is fixed (`Problem.pinned_starts`), a done task ends at its reported time, a task
  still running at `now` ends no earlier than `now` (else at its start plus its planned,
  possibly delayed, duration). The revision's instance records the fact in the task
  itself: its duration is the reported one, its release is its reported start, and it
  keeps no `after` and no deadline (it waits for nothing and is judged by nothing: it
  happened). Its successors keep their `after` and so wait for its real end.
- `delay {task_id, minutes}` lengthens a task by that many minutes on every robot (several
  delays of one task add up). A task already done cannot be delayed (its end is a fact).
- A task removed by the revision hands its own `after` to the tasks that waited for it, so
  the order of the trades around it is kept.

A pinned task without a report (an explicit pin of a task the site has not reported) is
committed to its robot only: it is planned from `now` like any unstarted task.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from app.domain.errors import DomainError
from app.domain.scheduling.reported import Reported, minutes_since, reported_interval

DELAY = "delay"


@dataclass(frozen=True)
class ReportedTimes:
    """A parent's execution report: its state and its times (aware, UTC)."""

    state: str
    started: datetime | None
    ended: datetime | None


@dataclass
class RevisionTimes:
    tasks: list[dict[str, Any]]  # the queue, facts and delays applied
    pinned_starts: dict[int, float] = field(default_factory=dict)
    not_before: float = 0.0
    # revision task index -> (start, end) minutes of each pinned task the site reported
    facts: dict[int, tuple[float, float]] = field(default_factory=dict)
    now: datetime | None = None  # the `now` the revision planned from (timed runs)


def _timed(tasks: Sequence[Mapping[str, Any]]) -> bool:
    return any(t.get("duration") is not None for t in tasks)


def _planned(task: Mapping[str, Any], robot: str) -> float:
    duration = task["duration"]
    if isinstance(duration, Mapping):
        return float(duration[robot])
    return float(duration)


def _lengthen(task: dict[str, Any], minutes: float) -> None:
    duration = task["duration"]
    if isinstance(duration, Mapping):
        task["duration"] = {r: float(d) + minutes for r, d in duration.items()}
    else:
        task["duration"] = float(duration) + minutes


def _delays(
    changes: Sequence[Mapping[str, Any]],
    queue: Sequence[Mapping[str, Any]],
    removed: Sequence[str],
) -> dict[str, float]:
    """Task id -> minutes to add, checked against the revision's queue."""
    ids = {str(t["id"]) for t in queue}
    out: dict[str, float] = {}
    for i, change in enumerate(changes):
        if change["type"] != DELAY:
            continue
        task_id, minutes = str(change["task_id"]), change["minutes"]
        if task_id not in ids:
            why = "it is removed by this revision" if task_id in removed else "no such task"
            raise DomainError(
                f"changes.{i}.task_id",
                f"cannot delay task '{task_id}': {why} in the revision's queue",
                code="unknown_task",
            )
        if not (isinstance(minutes, int | float) and minutes > 0):
            raise DomainError(
                f"changes.{i}.minutes",
                f"a delay lengthens a task by a positive number of minutes, got {minutes!r}",
            )
        out[task_id] = out.get(task_id, 0.0) + float(minutes)
    return out


def _change_index(changes: Sequence[Mapping[str, Any]], task_id: str) -> int:
    return next(
        i for i, c in enumerate(changes) if c["type"] == DELAY and str(c["task_id"]) == task_id
    )


def _link(entry: Any) -> tuple[str, str, float]:
    """(predecessor id, type, lag) of an `after` entry: a plain id or a link object."""
    if isinstance(entry, Mapping):
        return str(entry["task"]), str(entry.get("type", "FS")), float(entry.get("lag", 0))
    return str(entry), "FS", 0.0


def _inherit_after(
    queue: list[dict[str, Any]], parent_tasks: Sequence[Mapping[str, Any]], removed: Sequence[str]
) -> None:
    """Replace each removed task in an `after` list by what the removed task waited for.
    Typed links compose as a bridged milestone's do (docs/schedules.md#links): q -X?-> gone
    -?Z-> s becomes q -XZ-> s with the lags added; plain ones stay plain ids."""
    if not removed:
        return
    waits = {str(t["id"]): [_link(a) for a in t.get("after", ())] for t in parent_tasks}
    gone = set(removed)
    original = {str(t["id"]): t["id"] for t in parent_tasks}

    def resolve(link: tuple[str, str, float], seen: set[str]) -> list[tuple[str, str, float]]:
        task_id, kind, lag = link
        if task_id not in gone:
            return [link]
        out: list[tuple[str, str, float]] = []
        for p, first, more in waits.get(task_id, []):
            if p not in seen:
                seen.add(p)
                out.extend(resolve((p, first[0] + kind[1], more + lag), seen))
        return out

    for task in queue:
        after = [_link(a) for a in task.get("after", ())]
        if not gone & {a[0] for a in after}:
            continue
        kept: dict[tuple[str, str], float] = {}
        for a in after:
            for p, kind, lag in resolve(a, {a[0]}):
                kept[p, kind] = max(lag, kept.get((p, kind), lag))
        task["after"] = [
            original.get(p, p)
            if (kind, lag) == ("FS", 0.0)
            else {"task": original.get(p, p), "type": kind, "lag": lag}
            for (p, kind), lag in kept.items()
        ]


def plan_times(
    *,
    instance_data: Mapping[str, Any],
    queue: Sequence[Mapping[str, Any]],
    origin: Sequence[int | None],
    pinned: Mapping[int, str],
    reports: Mapping[int, ReportedTimes],
    changes: Sequence[Mapping[str, Any]],
    removed: Sequence[str],
    now: datetime | None,
    arrival: datetime,
) -> RevisionTimes:
    """The revision's queue in time. `origin` is each queue task's parent position (None:
    added); `pinned` maps revision task indexes to the robot (by name) they are pinned on;
    `reports` are the parent's, by parent position."""
    tasks = [dict(t) for t in queue]
    _inherit_after(tasks, instance_data["tasks"], removed)
    delays = _delays(changes, tasks, removed)
    if not _timed(tasks):
        if delays:
            first = _change_index(changes, next(iter(delays)))
            raise DomainError(
                f"changes.{first}",
                "a delay lengthens a task's duration, and this run is not timed (its tasks "
                "have no 'duration'); there is nothing to delay",
                code="untimed",
            )
        # An untimed run has no schedule: `now` changes nothing in it.
        return RevisionTimes(tasks=tasks)
    start_text = instance_data.get("start")
    origin_time = None if start_text is None else datetime.fromisoformat(start_text)
    if origin_time is None:
        if now is not None:
            raise DomainError(
                "now", "the run's plan has no start time, so 'now' cannot be placed in it"
            )
        not_before = 0.0
    elif now is not None:
        not_before = minutes_since(origin_time, now)
        if not_before < 0:
            raise DomainError(
                "now",
                f"{now.isoformat()} is before the plan's start {origin_time.isoformat()}; "
                "a revision plans from a time at or after the start",
                code="before_start",
            )
    else:
        not_before = max(0.0, minutes_since(origin_time, arrival))
    out = RevisionTimes(tasks=tasks, not_before=not_before, now=now or arrival)
    for index, task in enumerate(tasks):
        task_id = str(task["id"])
        extra = delays.get(task_id, 0.0)
        parent_index = origin[index]
        report = None if parent_index is None else reports.get(parent_index)
        facts = (
            index in pinned
            and origin_time is not None
            and report is not None
            and report.state in ("started", "done")
        )
        if not facts:
            if extra:
                _lengthen(task, extra)
            continue
        assert report is not None and origin_time is not None
        planned = _planned(task, pinned[index])
        if report.state == "done":
            if extra:
                i = _change_index(changes, task_id)
                raise DomainError(
                    f"changes.{i}.task_id",
                    f"task '{task_id}' was reported done; its end is a fact, a delay cannot "
                    "lengthen it",
                    code="task_done",
                )
            assert report.ended is not None
            seen = Reported(
                None if report.started is None else minutes_since(origin_time, report.started),
                minutes_since(origin_time, report.ended),
            )
        else:
            assert report.started is not None
            begun = minutes_since(origin_time, report.started)
            # Still running at `now`: it ends no earlier than `now`.
            seen = Reported(begun, max(begun + planned + extra, not_before))
        start, end = reported_interval(seen, planned)
        task["duration"] = end - start
        task["release"] = start
        task.pop("after", None)
        task.pop("deadline", None)
        out.pinned_starts[index] = start
        out.facts[index] = (start, end)
    return out
