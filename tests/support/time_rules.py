"""docs/living-plans.md#a-revision-in-time, written out for the tests: what a revision's schedule
must show, checked from the parent's instance, the site's reports and the request, on
plain values (so unit, API and end-to-end tests read the same rules), never through the
app's own `check_schedule`.

Slots are `{task_id (as text): (robot, start, end)}` in minutes of the plan.
"""

from __future__ import annotations

import itertools
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from datetime import timedelta
from typing import Any

Slots = Mapping[str, tuple[str, float, float]]
TOL = 1e-6


@dataclass(frozen=True)
class Report:
    state: str  # "started" or "done"
    start: float
    end: float | None = None  # done only


@dataclass
class TimeRules:
    parent_tasks: list[dict[str, Any]]  # the parent's instance tasks, as sent
    reports: dict[str, Report]
    now: float
    delays: dict[str, float] = field(default_factory=dict)
    unavailable: Collection[str] = ()
    parent_robots: Mapping[str, str] = field(default_factory=dict)  # task -> parent's robot

    def duration(self, task_id: str, robot: str) -> float:
        task = next(t for t in self.parent_tasks if str(t["id"]) == task_id)
        d = task["duration"]
        base = float(d[robot]) if isinstance(d, Mapping) else float(d)
        return base + self.delays.get(task_id, 0.0)

    def broken(self, slots: Slots) -> list[str]:
        """Every rule the slots break, as sentences; empty when they keep them all."""
        out: list[str] = []
        for task_id, report in self.reports.items():
            robot, start, end = slots[task_id]
            if abs(start - report.start) > TOL:
                out.append(f"{task_id} reported started at {report.start}, planned at {start}")
            if self.parent_robots and robot != self.parent_robots[task_id]:
                out.append(f"{task_id} ran on {self.parent_robots[task_id]}, planned on {robot}")
            if report.state == "done" and abs(end - (report.end or 0.0)) > TOL:
                out.append(f"{task_id} reported done at {report.end}, planned to end at {end}")
            if report.state == "started" and end < max(self.now, start) - TOL:
                out.append(f"{task_id} still runs at now {self.now}, planned to end at {end}")
        for task_id, (robot, start, end) in slots.items():
            if task_id in self.reports:
                continue
            if start < self.now - TOL:
                out.append(f"{task_id} unstarted but planned at {start}, before now {self.now}")
            if robot in self.unavailable:
                out.append(f"{task_id} planned on unavailable robot {robot}")
            want = self.duration(task_id, robot)
            if abs((end - start) - want) > TOL:
                out.append(f"{task_id} runs {end - start} min on {robot}, should take {want}")
            task = next(t for t in self.parent_tasks if str(t["id"]) == task_id)
            for before in task.get("after", ()):
                if str(before) in slots and start < slots[str(before)][2] - TOL:
                    out.append(
                        f"{task_id} starts at {start}, before {before} ends at "
                        f"{slots[str(before)][2]}"
                    )
        by_robot: dict[str, list[tuple[float, float, str]]] = {}
        for task_id, (robot, start, end) in slots.items():
            by_robot.setdefault(robot, []).append((start, end, task_id))
        for robot, mine in by_robot.items():
            mine.sort()
            for (_, end, a), (start, _, b) in itertools.pairwise(mine):
                if start < end - TOL:
                    out.append(f"{robot} runs {b} from {start} while {a} runs until {end}")
        return out


def slots_of(schedule: Mapping[str, Any]) -> dict[str, tuple[str, float, float]]:
    """The slots of a schedule JSON block (GET /runs/{id}/schedule, Schedule.to_dict)."""
    return {str(t["task_id"]): (t["robot"], t["start"], t["end"]) for t in schedule["tasks"]}


@dataclass
class History:
    """What the site did with some planned tasks, as execution report updates."""

    reports: dict[str, Report]
    late: str  # the done task that ran `late_by` minutes over
    waiting: list[str]  # the unreported tasks that wait for it: by `after`, or its robot's next
    updates: list[dict[str, Any]]


def site_history(
    schedule: Mapping[str, Any],
    task_ids: Collection[str],
    successors: Mapping[str, Collection[str]],
    start: Any,
    late_by: float,
) -> History:
    """Each robot did its `task_ids` in its planned order; its last one is still running,
    the others are done. The first done task (in queue order) that an unreported task
    waits for (by `after`, or as its robot's next task) ran `late_by` minutes over and
    pushed its robot's later reported tasks."""
    slots = slots_of(schedule)
    order = [str(t["task_id"]) for t in schedule["tasks"]]
    planned: dict[str, list[str]] = {}
    for task_id in sorted(slots, key=lambda t: (slots[t][1], slots[t][2], order.index(t))):
        planned.setdefault(slots[task_id][0], []).append(task_id)
    per_robot = {r: [t for t in mine if t in task_ids] for r, mine in planned.items()}
    done = {t for mine in per_robot.values() for t in mine[:-1]}

    def waits_for(task_id: str) -> list[str]:
        mine = planned[slots[task_id][0]]
        following = mine[mine.index(task_id) + 1 : mine.index(task_id) + 2]
        return [t for t in [*successors.get(task_id, ()), *following] if t not in task_ids]

    late = next(t for t in order if t in done and waits_for(t))
    reports: dict[str, Report] = {}
    for mine in per_robot.values():
        shift = 0.0
        for k, task_id in enumerate(mine):
            _, begin, end = slots[task_id]
            begin, end = begin + shift, end + shift
            if task_id == late:
                end += late_by
                shift += late_by
            last = k == len(mine) - 1
            reports[task_id] = Report("started", begin) if last else Report("done", begin, end)

    def at(minute: float) -> str:
        return str((start + timedelta(minutes=minute)).isoformat())

    updates: list[dict[str, Any]] = []
    for task_id in order:
        report = reports.get(task_id)
        if report is None:
            continue
        key: Any = int(task_id) if task_id.isdigit() else task_id
        updates.append({"task_id": key, "state": "started", "at": at(report.start)})
        if report.state == "done":
            assert report.end is not None
            updates.append({"task_id": key, "state": "done", "at": at(report.end)})
    return History(reports, late, waits_for(late), updates)
