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
from app.domain.modes import Mode, default_max_deviation
from app.domain.problem import Problem
from app.domain.serialize import instance_from_dict
from app.plans.revision_pins import ParentDecision, pinned_rows
from app.plans.revision_times import DELAY, ReportedTimes, plan_times
from app.runs.spec import RunSpec

_TASK_TIME = ("duration", "after", "zone", "release", "deadline")


class ChangeType:
    ROBOT_UNAVAILABLE = "robot_unavailable"
    ROBOT_AVAILABLE = "robot_available"
    SET_RATES = "set_rates"
    ADD_ROBOT = "add_robot"
    ADD_TASKS = "add_tasks"
    REMOVE_TASKS = "remove_tasks"
    SET_MODE = "set_mode"
    DELAY = DELAY


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


def _names(robots: Sequence[Mapping[str, Any]]) -> list[str]:
    return [str(r["name"]) for r in robots]


def _robot_index(robots: Sequence[Mapping[str, Any]], name: str, where: str) -> int:
    names = _names(robots)
    if name not in names:
        raise DomainError(
            where, f"unknown robot '{name}'; the fleet is {', '.join(names)}", code="unknown_robot"
        )
    return names.index(name)


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
    _contradictions(changes)
    data = parent_spec.instance_data
    robots = [dict(r, success=dict(r["success"])) for r in data["robots"]]
    tasks = [dict(t) for t in data["tasks"]]
    parent_names = _names(robots)
    unavailable = {parent_names[i] for i in parent_spec.unavailable or []}
    mode = Mode(parent_spec.mode)
    cap_from_change: tuple[bool, float | None] | None = None
    mode_changed = False
    fleet_changes: list[dict[str, Any]] = []
    features = {f for t in tasks for f in t["features"]}
    # The fleet first: which robots are unavailable decides what may stay pinned.
    for i, c in enumerate(changes):
        kind = c["type"]
        if kind == ChangeType.ROBOT_UNAVAILABLE:
            _robot_index(robots, c["robot"], f"changes.{i}.robot")
            unavailable.add(c["robot"])
            fleet_changes.append({"robot": c["robot"], "change": "unavailable"})
        elif kind == ChangeType.ROBOT_AVAILABLE:
            _robot_index(robots, c["robot"], f"changes.{i}.robot")
            unavailable.discard(c["robot"])
            fleet_changes.append({"robot": c["robot"], "change": "available"})
        elif kind == ChangeType.SET_RATES:
            r = _robot_index(robots, c["robot"], f"changes.{i}.robot")
            for f in c["success"]:
                if f not in robots[r]["success"]:
                    raise DomainError(
                        f"changes.{i}.success.{f}",
                        f"robot '{c['robot']}' has no rate for feature '{f}'; it rates "
                        f"{', '.join(sorted(robots[r]['success']))}",
                        code="unknown_feature",
                    )
            robots[r]["success"].update(c["success"])
            fleet_changes.append({"robot": c["robot"], "change": "rates", "success": c["success"]})
        elif kind == ChangeType.ADD_ROBOT:
            new = c["robot"]
            if new["name"] in _names(robots):
                raise DomainError(
                    f"changes.{i}.robot.name",
                    f"robot '{new['name']}' is already in the fleet",
                    code="duplicate_robot",
                )
            missing = sorted(features - set(new["success"]))
            if missing:
                raise DomainError(
                    f"changes.{i}.robot.success",
                    f"robot '{new['name']}' must rate every feature; missing {missing}",
                    code="unknown_feature",
                )
            robots.append(
                {
                    "name": new["name"],
                    "label": new.get("label", ""),
                    "description": new.get("description", ""),
                    "success": dict(new["success"]),
                }
            )
            fleet_changes.append({"robot": new["name"], "change": "added"})
        elif kind == ChangeType.SET_MODE:
            mode, mode_changed = Mode(c["mode"]), True
            if "max_deviation" in c:
                cap_from_change = (True, c["max_deviation"])
    if len(unavailable) == len(robots):
        raise DomainError(
            "changes",
            "every robot would be unavailable; no robot is left for the unpinned tasks",
            code="no_robot_left",
        )

    # Pins: what the rule names, less failed tasks and tasks started (not done) on a robot
    # that is now unavailable.
    candidates = _pin_candidates(pin, decided, tasks, execution)
    pinned_parent = [
        t
        for t in candidates
        if execution.get(t) != "failed"
        and not (execution.get(t) == "started" and decided[t].record.robot_name in unavailable)
    ]
    pinned_ids = {str(tasks[t]["id"]) for t in pinned_parent}

    # The queue: the parent's order, removals dropped, additions after the last pin or at
    # the end.
    removed: list[str] = []
    added_next: list[dict[str, Any]] = []
    added_end: list[dict[str, Any]] = []
    known = {str(t["id"]) for t in tasks}
    for i, c in enumerate(changes):
        kind = c["type"]
        if kind == ChangeType.REMOVE_TASKS:
            for j, task_id in enumerate(str(t) for t in c["task_ids"]):
                where = f"changes.{i}.task_ids.{j}"
                if task_id in pinned_ids:
                    raise DomainError(
                        where,
                        f"task '{task_id}' is pinned (done or committed); a pinned task "
                        "cannot be removed",
                        code="pinned_task",
                    )
                if task_id not in known or task_id in removed:
                    raise DomainError(
                        where, f"unknown task '{task_id}' in the queue", code="unknown_task"
                    )
                removed.append(task_id)
        elif kind == ChangeType.ADD_TASKS:
            for j, task in enumerate(c["tasks"]):
                task_id = str(task["id"])
                where = f"changes.{i}.tasks.{j}.id"
                if task_id in pinned_ids:
                    raise DomainError(
                        where,
                        f"task '{task_id}' is pinned; it cannot be added again",
                        code="pinned_task",
                    )
                if task_id in known:
                    raise DomainError(
                        where,
                        f"task id '{task_id}' is already in the queue",
                        code="duplicate_task",
                    )
                known.add(task_id)
                entry = {
                    "id": task["id"],
                    "name": task.get("name") or str(task["id"]),
                    "type": task.get("type", "Custom"),
                    "features": list(task["features"]),
                    # docs/living-plans.md#a-revision-in-time: an added task of a timed run brings
                    # its own time fields.
                    **{k: task[k] for k in _TASK_TIME if task.get(k) is not None},
                }
                (added_next if c.get("position", "end") == "next" else added_end).append(entry)
    last_pin = max(pinned_parent) if pinned_parent else -1
    queue: list[dict[str, Any]] = []
    origin: list[int | None] = []  # parent position of each revision task (None: added)
    if last_pin < 0:
        queue.extend(added_next)
        origin.extend([None] * len(added_next))
    for t, task in enumerate(tasks):
        if str(task["id"]) not in removed:
            queue.append(task)
            origin.append(t)
        if t == last_pin:
            queue.extend(added_next)
            origin.extend([None] * len(added_next))
    queue.extend(added_end)
    origin.extend([None] * len(added_end))

    names = _names(robots)
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
        removed=removed,
        now=now,
        arrival=arrival or datetime.now(UTC),
    )
    # The parent's other instance fields (docs/living-plans.md#a-revision-in-time: travel, start)
    # are the site's: kept.
    instance_data = {**data, "tasks": times.tasks, "robots": robots}
    try:
        instance = instance_from_dict(instance_data)
    except DomainError as exc:
        raise DomainError("changes", exc.message, code=exc.code) from None
    pinned = {i: names.index(robot) for i, robot in pinned_on.items()}
    off = {names.index(n) for n in unavailable}

    # The cap: set_mode's, else the parent's explicit cap kept, else the mode default for
    # the new W (Problem.build computes it from max_deviation None).
    explicit = parent_spec.cap_explicit
    if explicit is None:  # stored before the flag existed: a default equals its mode's
        parent_problem = parent_spec.problem
        default = default_max_deviation(
            Mode(parent_spec.mode),
            parent_problem.cap.n_tasks,
            parent_problem.cap.n_robots,
        )
        explicit = parent_spec.max_deviation != default
    if cap_from_change is not None:
        max_dev, keep = cap_from_change[1], True
    elif mode_changed or not explicit:
        max_dev, keep = None, False
    else:
        max_dev, keep = parent_spec.max_deviation, True
    try:
        problem = Problem.build(
            instance,
            mode,
            max_dev,
            uncapped=keep and max_dev is None,
            pinned=pinned,
            unavailable=off,
            pinned_starts=times.pinned_starts,
            not_before=times.not_before,
        )
    except InfeasibleCapError as exc:
        raise InfeasibleCapError(
            f"the revision's pins and fleet break the workload cap: {exc.message}",
            field="pin",
            suggested_max_deviation=exc.suggested_max_deviation,
        ) from None
    except DomainError as exc:
        raise DomainError("changes", exc.message, code=exc.code) from None

    # Everything not named here is inherited as it is (quality threshold, retries,
    # temperature, guidance, seed, LLM scope, and whatever a run spec gains later).
    spec = replace(
        parent_spec,
        instance_data=instance_data,
        mode=mode.value,
        max_deviation=problem.cap.max_deviation,
        reasoner=reasoner or parent_spec.reasoner,
        model=model if model is not None else (None if reasoner else parent_spec.model),
        token_budget=token_budget,
        replay_of=None,
        cap_explicit=keep,
        pinned={str(t): r for t, r in sorted(pinned.items())},
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
        added_tasks=[str(t["id"]) for t in added_next + added_end],
        removed_tasks=removed,
        fleet_changes=fleet_changes,
        now=times.now if instance.timed else None,
        facts=times.facts,
    )
