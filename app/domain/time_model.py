"""The time fields of a timed instance as indexes and numbers: what schedulers read.

Built once by `app.domain.timing_rules.check_timing` after every rule held, so everything
here may assume a valid instance: every task has a duration on at least one robot, `after`
names known tasks without a cycle, every pair of zones in use has a travel time.

Conventions (docs/schedules.md#the-model): minutes from the plan's start (minute 0 is `start` on the
wall clock); a missing release is 0, a missing deadline or shift end is unbounded (`math.inf`);
a robot with no start zone starts where its first task is (no travel before it); tasks
have no zone only when no task has one, and then nothing ever travels.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from functools import cached_property

import numpy as np

from app.domain.links import Arc, Times, earliest_start


@dataclass(frozen=True)
class TimeModel:
    # durations[t][r]: minutes robot r takes for task t; None: r cannot take t.
    durations: tuple[tuple[float | None, ...], ...]
    # Per task its incoming links (predecessor index, type, lag): docs/schedules.md#links.
    links: tuple[tuple[Arc, ...], ...]
    release: tuple[float, ...]
    deadline: tuple[float, ...]  # math.inf when none
    zones: tuple[str, ...]  # every zone in use, in first-seen order
    task_zone: tuple[int | None, ...]  # index into zones; None when no task has a zone
    robot_zone: tuple[int | None, ...]  # start zone; None: starts at its first task
    travel_minutes: tuple[tuple[float, ...], ...]  # zones x zones, 0 on the diagonal
    shifts: tuple[tuple[float, float], ...]  # per robot [start, end]; (0, inf) when none
    start: datetime | None

    @property
    def n_tasks(self) -> int:
        return len(self.durations)

    @property
    def n_robots(self) -> int:
        return len(self.shifts)

    def duration(self, task: int, robot: int) -> float:
        d = self.durations[task][robot]
        if d is None:
            raise ValueError(f"robot {robot} cannot take task {task}: no duration for it")
        return d

    def eligible_robots(self, task: int) -> tuple[int, ...]:
        return tuple(r for r, d in enumerate(self.durations[task]) if d is not None)

    def shortest(self, task: int) -> float:
        return min(d for d in self.durations[task] if d is not None)

    def eligibility(self) -> np.ndarray:
        return np.array([[d is not None for d in row] for row in self.durations], dtype=bool)

    def without(self, allowed: np.ndarray) -> TimeModel:
        """The same model where the pairs `allowed` forbids (robots' skills) have no duration."""
        durations = tuple(
            tuple(d if allowed[t, r] else None for r, d in enumerate(row))
            for t, row in enumerate(self.durations)
        )
        return dataclasses.replace(self, durations=durations)

    def travel(self, zone_from: int | None, zone_to: int | None) -> float:
        """Minutes from one zone to another; 0 when either end has no zone."""
        if zone_from is None or zone_to is None:
            return 0.0
        return self.travel_minutes[zone_from][zone_to]

    def travel_to_task(self, zone_from: int | None, task: int) -> float:
        return self.travel(zone_from, self.task_zone[task])

    @cached_property
    def has_travel(self) -> bool:
        return any(m > 0 for row in self.travel_minutes for m in row)

    @cached_property
    def predecessors(self) -> tuple[tuple[int, ...], ...]:
        """Per task the indexes of the tasks it waits for, each once, whatever the links'
        types: placing a task after these is what every scheduler does."""
        return tuple(tuple(dict.fromkeys(a.pred for a in arcs)) for arcs in self.links)

    @cached_property
    def typed(self) -> bool:
        """Is any link other than a plain finish-to-start with no lag?"""
        return any(not a.plain for arcs in self.links for a in arcs)

    def ready(self, task: int, duration: float, starts: Times, ends: Times) -> float:
        """The earliest start the task's links allow on a robot taking `duration` minutes,
        its predecessors at `starts`/`ends` (0 without any; release not included)."""
        return earliest_start(self.links[task], duration, starts, ends)

    @cached_property
    def successor_links(self) -> tuple[tuple[tuple[int, Arc], ...], ...]:
        """Per task the links out of it: (successor index, the successor's arc)."""
        out: list[list[tuple[int, Arc]]] = [[] for _ in range(self.n_tasks)]
        for t, arcs in enumerate(self.links):
            for a in arcs:
                out[a.pred].append((t, a))
        return tuple(tuple(x) for x in out)

    @cached_property
    def successors(self) -> tuple[tuple[int, ...], ...]:
        out: list[list[int]] = [[] for _ in range(self.n_tasks)]
        for t, preds in enumerate(self.predecessors):
            for p in preds:
                out[p].append(t)
        return tuple(tuple(s) for s in out)

    @cached_property
    def order(self) -> tuple[int, ...]:
        """A precedence order: each task after its predecessors, else queue order."""
        order = topological_order(self.predecessors)
        if order is None:  # check_timing refuses cycles before a TimeModel exists
            raise ValueError("precedence cycle")
        return tuple(order)

    @cached_property
    def earliest(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Per task lower bounds on its start and its end in any schedule: release and links
        on the shortest durations, robots ignored (the chain rule of
        docs/schedules.md#the-model). A link bounding a task's end (FF, SF) bounds its start
        by that less its longest duration, since the robot is not known."""
        starts = [0.0] * self.n_tasks
        finish = [0.0] * self.n_tasks
        for t in self.order:
            longest = max(d for d in self.durations[t] if d is not None)
            start = max(self.ready(t, longest, starts, finish), self.release[t])
            finish[t] = max(self.ready(t, 0.0, starts, finish), start + self.shortest(t))
            starts[t] = max(start, finish[t] - longest)
        return tuple(starts), tuple(finish)

    @property
    def earliest_finish(self) -> tuple[float, ...]:
        return self.earliest[1]


def topological_order(predecessors: Sequence[Sequence[int]]) -> list[int] | None:
    """Kahn's algorithm, smallest ready index first (so queue order among ready tasks);
    None if there is a cycle."""
    n = len(predecessors)
    waiting = [len(set(p)) for p in predecessors]
    successors: list[list[int]] = [[] for _ in range(n)]
    for t, preds in enumerate(predecessors):
        for p in set(preds):
            successors[p].append(t)
    ready = [t for t in range(n) if waiting[t] == 0]
    heapq.heapify(ready)
    order: list[int] = []
    while ready:
        t = heapq.heappop(ready)
        order.append(t)
        for s in successors[t]:
            waiting[s] -= 1
            if waiting[s] == 0:
                heapq.heappush(ready, s)
    return order if len(order) == n else None


def unbounded(value: float | None) -> float:
    return math.inf if value is None else float(value)
