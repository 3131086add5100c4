"""docs/schedules.md#a-schedule-and-its-check written out again for the tests, from the request body
alone: a feasibility check of a returned schedule block, and an exhaustive search for the best
makespan.

Nothing here calls the app: the rules are read from the request's tasks, robots and travel,
so a mistake in app.domain.scheduling cannot vouch for itself.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence
from typing import Any

EPS = 1e-6


class Site:
    """A timed request body, as numbers: durations per robot, predecessors, zones, the
    quickest travel between zones, releases, deadlines, shifts."""

    def __init__(self, body: dict[str, Any]) -> None:
        self.tasks: list[dict[str, Any]] = body["tasks"]
        self.robots: list[dict[str, Any]] = body["robots"]
        self.names = [r["name"] for r in self.robots]
        self.index = {str(t["id"]): i for i, t in enumerate(self.tasks)}
        self.preds = [[self.index[str(p)] for p in t.get("after", [])] for t in self.tasks]
        zones = sorted(
            {t["zone"] for t in self.tasks if t.get("zone")}
            | {r["zone"] for r in self.robots if r.get("zone")}
        )
        given = body.get("travel") or {}
        self.travel: dict[tuple[str, str], float] = {}
        for a in zones:
            for b in zones:
                pair = given.get(a, {}).get(b, given.get(b, {}).get(a))
                self.travel[a, b] = 0.0 if a == b else (math.inf if pair is None else pair)
        # A robot takes the quickest route (docs/schedules.md#the-model: travel), Floyd-Warshall.
        for k in zones:
            for a in zones:
                for b in zones:
                    via = self.travel[a, k] + self.travel[k, b]
                    if via < self.travel[a, b]:
                        self.travel[a, b] = via

    def duration(self, t: int, r: int) -> float | None:
        d = self.tasks[t]["duration"]
        if isinstance(d, dict):
            return d.get(self.names[r])
        return float(d)

    def shift(self, r: int) -> tuple[float, float]:
        a, b = self.robots[r].get("available") or (0, math.inf)
        return float(a), float(b)

    def moves(self, zone_from: str | None, zone_to: str | None) -> float:
        if zone_from is None or zone_to is None:
            return 0.0
        return self.travel[zone_from, zone_to]

    def release(self, t: int) -> float:
        return float(self.tasks[t].get("release") or 0)

    def deadline(self, t: int) -> float:
        d = self.tasks[t].get("deadline")
        return math.inf if d is None else float(d)


def feasibility_errors(body: dict[str, Any], schedule: dict[str, Any]) -> list[str]:
    """Every docs/schedules.md#a-schedule-and-its-check rule the schedule block breaks: one task
    each, eligibility, duration, precedence, one task at a time with travel between zones (from the
    start zone after the shift starts), release, deadline, shift."""
    site = Site(body)
    rows = schedule["tasks"]
    errors: list[str] = []
    if [str(r["task_id"]) for r in rows] != [str(t["id"]) for t in site.tasks]:
        return ["not one row per task in queue order"]
    robot_of = [site.names.index(r["robot"]) for r in rows]
    for t, row in enumerate(rows):
        r = robot_of[t]
        d = site.duration(t, r)
        if d is None:
            errors.append(f"{row['task_id']}: robot {row['robot']} may not take it")
            continue
        if abs(row["end"] - row["start"] - d) > EPS:
            errors.append(f"{row['task_id']}: runs {row['end'] - row['start']}, takes {d}")
        for p in site.preds[t]:
            if row["start"] < rows[p]["end"] - EPS:
                errors.append(f"{row['task_id']}: starts before {rows[p]['task_id']} ends")
        if row["start"] < site.release(t) - EPS:
            errors.append(f"{row['task_id']}: starts before its release")
        if row["end"] > site.deadline(t) + EPS:
            errors.append(f"{row['task_id']}: ends after its deadline")
        a, b = site.shift(r)
        if row["start"] < a - EPS or row["end"] > b + EPS:
            errors.append(f"{row['task_id']}: outside the shift of {row['robot']}")
    for r, robot in enumerate(site.robots):
        mine = sorted(
            (t for t in range(len(rows)) if robot_of[t] == r), key=lambda t: rows[t]["start"]
        )
        ready, here = site.shift(r)[0], robot.get("zone")
        for t in mine:
            zone = site.tasks[t].get("zone")
            if here is None:  # no start zone: the robot starts where its first task is
                here = zone
            if rows[t]["start"] < ready + site.moves(here, zone) - EPS:
                errors.append(f"{rows[t]['task_id']}: {robot['name']} cannot be there yet")
            ready, here = rows[t]["end"], zone
    return errors


def loads_within_cap(body: dict[str, Any], answer: dict[str, Any]) -> bool:
    cap = answer["max_deviation"]
    if cap is None:
        return True
    w = len(body["tasks"]) / len(body["robots"])
    return all(
        math.ceil(w - cap - 1e-9)
        <= answer["metrics"]["workload"].get(r["name"], 0)
        <= math.floor(w + cap + 1e-9)
        for r in body["robots"]
    )


def earliest_makespan(site: Site, robots: Sequence[int], orders: Sequence[Sequence[int]]) -> float:
    """The makespan of each task at its earliest start given the robots and each robot's
    order (a semi-active schedule: for fixed orders, starting earlier never hurts), or inf
    when the orders contradict precedence or a deadline or shift cannot be met."""
    n = len(robots)
    previous: dict[int, int] = {}
    for order in orders:
        for q, t in itertools.pairwise(order):
            previous[t] = q
    end: dict[int, float] = {}
    while len(end) < n:
        ready = [
            t
            for t in range(n)
            if t not in end
            and all(p in end for p in site.preds[t])
            and (t not in previous or previous[t] in end)
        ]
        if not ready:
            return math.inf  # a robot's order waits on a task that waits on it
        for t in ready:
            r, zone = robots[t], site.tasks[t].get("zone")
            d = site.duration(t, r)
            if d is None:
                return math.inf
            a, b = site.shift(r)
            if t in previous:
                q = previous[t]
                start = end[q] + site.moves(site.tasks[q].get("zone"), zone)
            else:
                start = a + site.moves(site.robots[r].get("zone") or zone, zone)
            start = max([start, site.release(t), *(end[p] for p in site.preds[t])])
            if start + d > min(site.deadline(t), b) + EPS:
                return math.inf
            end[t] = start + d
    return max(end.values())


def _orders(robots: Sequence[int], n_robots: int) -> Iterator[list[list[int]]]:
    groups = [[t for t, r in enumerate(robots) if r == k] for k in range(n_robots)]
    for combo in itertools.product(*(itertools.permutations(g) for g in groups)):
        yield [list(order) for order in combo]


def best_makespan(
    body: dict[str, Any],
    success: Sequence[Sequence[float]],
    loads: tuple[int, int] | None,
    *,
    success_first: bool,
) -> tuple[float, float]:
    """Exhaustively: over every assignment (loads within [lo, hi] when given) and every
    order per robot, the best (expected success, makespan). `success_first`: the highest
    ES that has a feasible schedule, then the shortest makespan at it
    (`success_then_makespan`); else the shortest makespan at any ES (`makespan`)."""
    if not success_first:
        success = [[0.0] * len(row) for row in success]  # every ES ties: makespan decides
    site = Site(body)
    n, m = len(site.tasks), len(site.robots)
    best: tuple[float, float] = (-1.0, math.inf)
    for robots in itertools.product(range(m), repeat=n):
        if loads is not None and not all(loads[0] <= robots.count(k) <= loads[1] for k in range(m)):
            continue
        es = sum(success[t][r] for t, r in enumerate(robots)) / n
        if es < best[0] - 1e-9:
            continue
        span = min(earliest_makespan(site, robots, o) for o in _orders(robots, m))
        if span == math.inf:
            continue
        if es > best[0] + 1e-9:
            best = (es, span)
        elif span < best[1]:
            best = (best[0], span)
    return best
