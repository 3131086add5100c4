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
        # Per task its links (predecessor, type, lag): a plain id is FS with no lag
        # (docs/schedules.md#links).
        self.links = [[self._link(a) for a in t.get("after", [])] for t in self.tasks]
        self.preds = [[p for p, _, _ in links] for links in self.links]
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

    def _link(self, entry: Any) -> tuple[int, str, float]:
        if isinstance(entry, dict):
            kind, lag = entry.get("type", "FS"), float(entry.get("lag", 0))
            return self.index[str(entry["task"])], kind, lag
        return self.index[str(entry)], "FS", 0.0

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
    # A team task (docs/allocation.md#teams) holds every member: each is checked as its robot.
    crew_of = [
        [site.names.index(m["robot"]) for m in r.get("team") or []] or [robot_of[t]]
        for t, r in enumerate(rows)
    ]
    for t, row in enumerate(rows):
        r = robot_of[t]
        d = site.duration(t, r)
        if d is None:
            errors.append(f"{row['task_id']}: robot {row['robot']} may not take it")
            continue
        if abs(row["end"] - row["start"] - d) > EPS:
            errors.append(f"{row['task_id']}: runs {row['end'] - row['start']}, takes {d}")
        for p, kind, lag in site.links[t]:
            # FS start >= end(p) + lag, SS start >= start(p) + lag, FF end >= end(p) + lag,
            # SF end >= start(p) + lag
            theirs = rows[p]["start"] if kind[0] == "S" else rows[p]["end"]
            mine = row["start"] if kind[1] == "S" else row["end"]
            if mine < theirs + lag - EPS:
                errors.append(
                    f"{row['task_id']}: breaks its {kind} {lag:+g} from {rows[p]['task_id']}"
                )
        if row["start"] < site.release(t) - EPS:
            errors.append(f"{row['task_id']}: starts before its release")
        if row["end"] > site.deadline(t) + EPS:
            errors.append(f"{row['task_id']}: ends after its deadline")
        for m in crew_of[t]:
            a, b = site.shift(m)
            if row["start"] < a - EPS or row["end"] > b + EPS:
                errors.append(f"{row['task_id']}: outside the shift of {site.names[m]}")
    for r, robot in enumerate(site.robots):
        mine = sorted(
            (t for t in range(len(rows)) if r in crew_of[t]), key=lambda t: rows[t]["start"]
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
    when no times keep the orders, the links, the deadlines and shifts.

    Every rule but the deadlines and shift ends is a lower bound "start(v) >= start(u) + w"
    (a link, the robot's previous task and the travel) or a floor (release, shift start
    and the way from the start zone), so the earliest starts are the longest paths, found
    by relaxing until nothing moves (Bellman-Ford); still moving after n rounds means a
    positive cycle: the orders contradict the links."""
    n = len(robots)
    dur: list[float] = []
    for t in range(n):
        d = site.duration(t, robots[t])
        if d is None:
            return math.inf
        dur.append(d)
    edges: list[tuple[int, int, float]] = []  # start[v] >= start[u] + w
    for t in range(n):
        for p, kind, lag in site.links[t]:
            w = (dur[p] if kind[0] == "F" else 0.0) + lag - (dur[t] if kind[1] == "F" else 0.0)
            edges.append((p, t, w))
    start = [site.release(t) for t in range(n)]
    for order in orders:
        for q, t in itertools.pairwise(order):
            move = site.moves(site.tasks[q].get("zone"), site.tasks[t].get("zone"))
            edges.append((q, t, dur[q] + move))
        if order:
            first, r = order[0], robots[order[0]]
            zone = site.tasks[first].get("zone")
            way = site.moves(site.robots[r].get("zone") or zone, zone)
            start[first] = max(start[first], site.shift(r)[0] + way)
    for _ in range(n + 1):
        moved = False
        for u, v, w in edges:
            if start[u] + w > start[v] + EPS:
                start[v] = start[u] + w
                moved = True
        if not moved:
            break
    else:
        return math.inf
    for t in range(n):
        if start[t] + dur[t] > min(site.deadline(t), site.shift(robots[t])[1]) + EPS:
            return math.inf
    return max((start[t] + dur[t] for t in range(n)), default=0.0)


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
