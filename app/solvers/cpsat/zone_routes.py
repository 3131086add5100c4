"""Each robot's shortest routes through the zones it may enter: the prices of the load
LP's route columns (`load_bound`, docs/schedules.md#bounds). A robot that enters a set of
zones walks from its start zone through all of them in some order, each leg at least the
shortest way between its ends, so its travel is at least the set's route here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from app.domain.problem import Problem

# Routes through every set of the zones a robot may enter, up to this many zones (2^n - 1
# route columns per robot); a robot that may enter more keeps the entries alone.
ROUTE_ZONES = 6


def zone_routes(
    problem: Problem, visits: Sequence[tuple[int, int, float, list[int]]]
) -> list[tuple[int, list[int], float]]:
    """Per robot and set of the zones it may enter (at most `ROUTE_ZONES` of them), the
    visit columns of the set and the shortest way from its start zone through every zone
    of the set (from the first, for a robot without one), over the shortest ways between
    zones (a robot passing through a zone on the way only makes its route longer)."""
    tm = problem.instance.timing
    way = shortest_ways(tm.travel_minutes)
    by_robot: dict[int, list[int]] = {}
    for j, (r, *_) in enumerate(visits):
        by_robot.setdefault(r, []).append(j)
    out: list[tuple[int, list[int], float]] = []
    for r, columns in by_robot.items():
        if len(columns) > ROUTE_ZONES:
            continue
        zones = [visits[j][1] for j in columns]
        home = tm.robot_zone[r]
        for mask, minutes in route_minutes(way, home, zones).items():
            members = [columns[i] for i in range(len(zones)) if mask >> i & 1]
            out.append((r, members, minutes))
    return out


def route_minutes(
    way: Sequence[Sequence[float]], home: int | None, zones: Sequence[int]
) -> dict[int, float]:
    """For every non-empty set of `zones` (a bit mask over them), the shortest way from
    `home` (from whichever zone of the set comes first when None) visiting all of it."""
    n = len(zones)
    inf = math.inf
    # best[mask][i]: the shortest way from home through the zones of mask, ending at i
    best = [[inf] * n for _ in range(1 << n)]
    for i, z in enumerate(zones):
        best[1 << i][i] = 0.0 if home is None else way[home][z]
    for mask in range(1, 1 << n):
        for i in range(n):
            here = best[mask][i]
            if here == inf:
                continue
            for j in range(n):
                if not mask >> j & 1:
                    nxt = mask | 1 << j
                    best[nxt][j] = min(best[nxt][j], here + way[zones[i]][zones[j]])
    return {mask: min(best[mask]) for mask in range(1, 1 << n)}


def shortest_ways(travel: Sequence[Sequence[float]]) -> list[list[float]]:
    """The shortest way between every two zones (Floyd-Warshall over the travel)."""
    n = len(travel)
    way = [list(map(float, row)) for row in travel]
    for k in range(n):
        for a in range(n):
            for b in range(n):
                way[a][b] = min(way[a][b], way[a][k] + way[k][b])
    return way
