"""What a revision is (docs/living-plans.md#revisions), computed from its parent without touching
the database: the pins the rule selects, the fleet and queue after the changes, the cap, and the
pinned decision rows in the revision's own terms.

Changes arrive as plain dicts (the API validated their shape); every error here names the
request field it is about, so a bad revision is a 4xx before anything is written.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from typing import Any

from app.domain.errors import DomainError, InfeasibleCapError
from app.domain.models import Instance
from app.domain.modes import Mode, default_max_deviation
from app.domain.problem import Problem
from app.domain.serialize import instance_from_dict
from app.plans.revision_changes import (
    FLEET_HANDLERS,
    QUEUE_HANDLERS,
    ChangeType,
    Draft,
    apply_changes,
    fleet_names,
)
from app.plans.revision_pins import ParentDecision, pinned_rows
from app.plans.revision_times import ReportedTimes, RevisionTimes, plan_times
from app.runs.spec import RunSpec


@dataclass
class RevisionPlan:
    spec: RunSpec
    problem: Problem
    pinned_rows: list[dict[str, Any]]  # decision column values (pinned, pinned_from set)
    pinned_task_ids: list[str]
    added_tasks: list[str] = field(default_factory=list)
    removed_tasks: list[str] = field(default_factory=list)
    fleet_changes: list[dict[str, Any]] = field(default_factory=list)
    # docs/living-plans.md#a-revision-in-time: the `now` a timed revision planned from (None:
    # untimed), and the reported (start, end) minutes of its pinned tasks, by revision task index.
    now: datetime | None = None
    facts: dict[int, tuple[float, float]] = field(default_factory=dict)


def _contradictions(changes: Sequence[Mapping[str, Any]]) -> None:
    """A robot made unavailable and available, or a task added and removed, in one request."""
    off: dict[str, int] = {}
    on: dict[str, int] = {}
    added: dict[str, int] = {}
    removed: dict[str, int] = {}
    for i, c in enumerate(changes):
        kind = c["type"]
        if kind == ChangeType.ROBOT_UNAVAILABLE:
            off.setdefault(c["robot"], i)
        elif kind == ChangeType.ROBOT_AVAILABLE:
            on.setdefault(c["robot"], i)
        elif kind == ChangeType.ADD_TASKS:
            for t in c["tasks"]:
                added.setdefault(str(t["id"]), i)
        elif kind == ChangeType.REMOVE_TASKS:
            for t in c["task_ids"]:
                removed.setdefault(str(t), i)
    for robot in sorted(set(off) & set(on)):
        later = max(off[robot], on[robot])
        raise DomainError(
            f"changes.{later}",
            f"robot '{robot}' is made both unavailable (changes.{off[robot]}) and available "
            f"(changes.{on[robot]}) in one revision; send one of them",
            code="contradictory_changes",
        )
    for task in sorted(set(added) & set(removed)):
        later = max(added[task], removed[task])
        raise DomainError(
            f"changes.{later}",
            f"task '{task}' is both added (changes.{added[task]}) and removed "
            f"(changes.{removed[task]}) in one revision; send one of them",
            code="contradictory_changes",
        )


def _pin_candidates(
    pin: str | Mapping[str, Any],
    decided: Mapping[int, ParentDecision],
    tasks: Sequence[Mapping[str, Any]],
    execution: Mapping[int, str],
) -> list[int]:
    """Parent queue positions the rule names (before the exclusions)."""
    if pin == "reported":
        return sorted(t for t, s in execution.items() if s in ("started", "done") and t in decided)
    if pin == "decided":
        return sorted(decided)
    if not isinstance(pin, Mapping):
        raise DomainError("pin", f"unknown pin rule {pin!r}", code="invalid_pin")
    if "through_task_index" in pin:
        k = int(pin["through_task_index"])
        if k >= len(tasks):
            raise DomainError(
                "pin.through_task_index",
                f"{k} is past the parent's queue of {len(tasks)} tasks (0..{len(tasks) - 1})",
                code="invalid_pin",
            )
        undecided = [t for t in range(k + 1) if t not in decided]
        if undecided:
            raise DomainError(
                "pin.through_task_index",
                f"queue positions {undecided[:5]} (0..{k}) are not decided by the parent yet; "
                f"it has decided {len(decided)} task(s): pin only decided tasks",
                code="undecided_pin",
            )
        return list(range(k + 1))
    ids = [str(t) for t in pin["task_ids"]]
    position = {str(t["id"]): i for i, t in enumerate(tasks)}
    out: list[int] = []
    for j, task_id in enumerate(ids):
        if task_id not in position:
            raise DomainError(
                f"pin.task_ids.{j}", f"unknown task '{task_id}' in the parent", code="unknown_task"
            )
        if position[task_id] not in decided:
            raise DomainError(
                f"pin.task_ids.{j}",
                f"task '{task_id}' is not decided by the parent yet; pin only decided tasks",
                code="undecided_pin",
            )
        out.append(position[task_id])
    return sorted(set(out))


def _check_reasoner(parent_spec: RunSpec, reasoner: str | None) -> None:
    if parent_spec.reasoner == "replay" and reasoner is None:
        raise DomainError(
            "reasoner",
            "the parent replays a recorded run (reasoner 'replay'); a revision has no record "
            "to replay for its new tasks: name a reasoner (e.g. 'rules')",
            code="replay_needs_reasoner",
        )
    if reasoner == "replay":
        raise DomainError(
            "reasoner",
            "a revision cannot use the 'replay' reasoner: its new tasks have no recorded "
            "replies; name another reasoner",
            code="invalid_reasoner",
        )


def _queue(d: Draft, last_pin: int) -> tuple[list[dict[str, Any]], list[int | None]]:
    """The parent's order, removals dropped, additions after the last pin or at the end;
    with the parent position of each revision task (None: added)."""
    queue: list[dict[str, Any]] = []
    origin: list[int | None] = []
    if last_pin < 0:
        queue.extend(d.added_next)
        origin.extend([None] * len(d.added_next))
    for t, task in enumerate(d.tasks):
        if str(task["id"]) not in d.removed:
            queue.append(task)
            origin.append(t)
        if t == last_pin:
            queue.extend(d.added_next)
            origin.extend([None] * len(d.added_next))
    queue.extend(d.added_end)
    origin.extend([None] * len(d.added_end))
    return queue, origin


def _cap(parent_spec: RunSpec, d: Draft) -> tuple[float | None, bool]:
    """The cap and whether it is kept: set_mode's, else the parent's explicit cap kept, else
    the mode default for the new W (Problem.build computes it from max_deviation None)."""
    explicit = parent_spec.cap_explicit
    if explicit is None:  # stored before the flag existed: a default equals its mode's
        parent_problem = parent_spec.problem
        default = default_max_deviation(
            Mode(parent_spec.mode),
            parent_problem.cap.n_tasks,
            parent_problem.cap.n_robots,
        )
        explicit = parent_spec.max_deviation != default
    if d.cap_from_change is not None:
        return d.cap_from_change[1], True
    if d.mode_changed or not explicit:
        return None, False
    return parent_spec.max_deviation, True


def _pinned_parent(
    pin: str | Mapping[str, Any],
    decided: Mapping[int, ParentDecision],
    execution: Mapping[int, str],
    d: Draft,
) -> list[int]:
    """Pins: what the rule names, less failed tasks and tasks started (not done) on a robot
    that is now unavailable (a team task: on a team one of whose members is unavailable; it is
    re-formed, docs/living-plans.md#teams-in-a-revision)."""
    return [
        t
        for t in _pin_candidates(pin, decided, d.tasks, execution)
        if execution.get(t) != "failed"
        and not (
            execution.get(t) == "started" and not d.unavailable.isdisjoint(_members(decided[t]))
        )
    ]


def _members(parent: ParentDecision) -> list[str]:
    """The robots a parent decision holds: its team's members, or its robot."""
    team = parent.record.team
    return [str(m["robot"]) for m in team] if team else [parent.record.robot_name]


def _problem(
    instance: Instance,
    mode: Mode,
    max_dev: float | None,
    keep: bool,
    pinned: dict[int, int],
    off: set[int],
    times: RevisionTimes,
    teams: dict[int, list[int]],
) -> Problem:
    try:
        return Problem.build(
            instance,
            mode,
            max_dev,
            uncapped=keep and max_dev is None,
            pinned=pinned,
            unavailable=off,
            pinned_starts=times.pinned_starts,
            not_before=times.not_before,
            pinned_teams=teams,
        )
    except InfeasibleCapError as exc:
        raise InfeasibleCapError(
            f"the revision's pins and fleet break the workload cap: {exc.message}",
            field="pin",
            suggested_max_deviation=exc.suggested_max_deviation,
        ) from None
    except DomainError as exc:
        raise DomainError("changes", exc.message, code=exc.code) from None


def plan_revision(
    *,
    parent_spec: RunSpec,
    decided: Mapping[int, ParentDecision],
    execution: Mapping[int, str],
    changes: Sequence[Mapping[str, Any]],
    pin: str | Mapping[str, Any],
    reasoner: str | None,
    model: str | None,
    parent_id: str,
    token_budget: int | None,
    reports: Mapping[int, ReportedTimes] | None = None,
    now: datetime | None = None,
    arrival: datetime | None = None,
) -> RevisionPlan:
    _check_reasoner(parent_spec, reasoner)
    _contradictions(changes)
    data = parent_spec.instance_data
    d = Draft.from_parent(parent_spec)
    apply_changes(d, changes, FLEET_HANDLERS)
    if len(d.unavailable) == len(d.robots):
        raise DomainError(
            "changes",
            "every robot would be unavailable; no robot is left for the unpinned tasks",
            code="no_robot_left",
        )

    pinned_parent = _pinned_parent(pin, decided, execution, d)
    d.pinned_ids = {str(d.tasks[t]["id"]) for t in pinned_parent}
    apply_changes(d, changes, QUEUE_HANDLERS)
    queue, origin = _queue(d, max(pinned_parent) if pinned_parent else -1)

    names = fleet_names(d.robots)
    pinned_on = {
        i: decided[t].record.robot_name
        for i, t in enumerate(origin)
        if t is not None and t in pinned_parent
    }
    times = plan_times(
        instance_data=data,
        queue=queue,
        origin=origin,
        pinned=pinned_on,
        reports=reports or {},
        changes=changes,
        removed=d.removed,
        now=now,
        arrival=arrival or datetime.now(UTC),
    )
    # The parent's other instance fields (docs/living-plans.md#a-revision-in-time: travel, start)
    # are the site's: kept.
    instance_data = {**data, "tasks": times.tasks, "robots": d.robots}
    try:
        instance = instance_from_dict(instance_data)
    except DomainError as exc:
        raise DomainError("changes", exc.message, code=exc.code) from None
    pinned = {i: names.index(robot) for i, robot in pinned_on.items()}
    # A pinned team task keeps its whole team (docs/living-plans.md#teams-in-a-revision).
    teams = {
        i: [names.index(m) for m in _members(decided[t])]
        for i, t in enumerate(origin)
        if i in pinned and t is not None and decided[t].record.team
    }
    off = {names.index(n) for n in d.unavailable}
    max_dev, keep = _cap(parent_spec, d)
    problem = _problem(instance, d.mode, max_dev, keep, pinned, off, times, teams)

    # Everything not named here is inherited as it is (quality threshold, retries,
    # temperature, guidance, seed, LLM scope, and whatever a run spec gains later).
    spec = replace(
        parent_spec,
        instance_data=instance_data,
        mode=d.mode.value,
        max_deviation=problem.cap.max_deviation,
        reasoner=reasoner or parent_spec.reasoner,
        model=model if model is not None else (None if reasoner else parent_spec.model),
        token_budget=token_budget,
        replay_of=None,
        cap_explicit=keep,
        pinned={str(t): r for t, r in sorted(pinned.items())},
        pinned_teams={str(t): m for t, m in sorted(teams.items())} or None,
        unavailable=sorted(off),
        revision_of=parent_id,
        pinned_starts={str(t): m for t, m in sorted(times.pinned_starts.items())} or None,
        not_before=times.not_before if instance.timed else None,
    )
    return RevisionPlan(
        spec=spec,
        problem=problem,
        pinned_rows=pinned_rows(problem, origin, decided, times.facts),
        pinned_task_ids=[str(queue[i]["id"]) for i in sorted(pinned)],
        added_tasks=[str(t["id"]) for t in d.added_next + d.added_end],
        removed_tasks=d.removed,
        fleet_changes=d.fleet_changes,
        now=times.now if instance.timed else None,
        facts=times.facts,
    )
