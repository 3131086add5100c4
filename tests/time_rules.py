"""SPEC 16 "Time in living plans", written out for the tests: what a revision's schedule
must show, checked from the parent's instance, the site's reports and the request, on
plain values (so unit, API and end-to-end tests read the same rules), never through the
app's own `check_schedule`.

Slots are `{task_id (as text): (robot, start, end)}` in minutes of the plan.
"""

from __future__ import annotations

import itertools
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
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
