"""Seeded sites of the second family (docs/schedules.md#the-generator): unrelated robots.

Where `timed_instances.construction_site` derives a robot's minutes from its kind (a heavy
robot is slow at every careful task), here every (task, robot) duration is drawn on its
own, uniform in 5-40 whole minutes, as in Brandimarte's flexible job shops: a robot quick
at one task says nothing about the next, so a plan has to follow the speeds.

- Zones: `n_zones` (4 by default), a random whole travel time of 2-9 minutes between any
  two, then closed under the shortest way (Floyd-Warshall), so the matrix is a metric and
  no plan gains by passing through a third zone. Each task lies in a zone drawn uniformly.
- Precedence within a window: 60% of the tasks wait for one or two (even odds) of the 30
  tasks before them in queue order, so the queue is a topological order and any prefix is
  an instance.
- Releases: 10% of the tasks are released at a whole minute drawn uniformly from the
  first half of the quick load (`n_tasks` x 8 / `n_robots`: each task at about its
  quickest robot's minutes, spread over the robots).
- Robots start in zone `i mod n_zones`, all from minute 0, with one shift as long as a
  week; every robot rates the one feature 0.9, so every allocation has the same expected
  success and the makespan alone decides (no workload cap: `Problem.build(...,
  uncapped=True)`, as for Brandimarte's shops).

Sizes used by the benchmark: 200 x 5, 600 x 12 and 1,000 x 20, 4 zones each.
"""

from __future__ import annotations

import random

from app.domain.models import Instance, Robot, Task

FEATURE = "work"
MINUTES = (5, 40)
TRAVEL = (2, 9)
WINDOW = 30
SHARE_AFTER = 0.6
SHARE_RELEASED = 0.1
QUICK_MINUTES = 8  # about the least of 12-20 draws of 5-40: the release window's scale
WEEK = 7 * 24 * 60


def zone_name(z: int) -> str:
    return f"Z{z + 1}"


def metric_travel(rng: random.Random, n_zones: int) -> list[list[int]]:
    """Random symmetric travel of `TRAVEL` minutes, closed under the shortest way."""
    way = [[0] * n_zones for _ in range(n_zones)]
    for a in range(n_zones):
        for b in range(a + 1, n_zones):
            way[a][b] = way[b][a] = rng.randint(*TRAVEL)
    for k in range(n_zones):
        for a in range(n_zones):
            for b in range(n_zones):
                way[a][b] = min(way[a][b], way[a][k] + way[k][b])
    return way


def unrelated_site(n_tasks: int, n_robots: int, *, n_zones: int = 4, seed: int = 0) -> Instance:
    """A site of `n_tasks` tasks and `n_robots` robots of the second family."""
    rng = random.Random(seed)
    way = metric_travel(rng, n_zones)
    robots = tuple(
        Robot(
            name=f"r{i + 1}",
            success={FEATURE: 0.9},
            label=f"Robot {i + 1}",
            zone=zone_name(i % n_zones),
            available=(0, WEEK),
        )
        for i in range(n_robots)
    )
    release_until = n_tasks * QUICK_MINUTES // (2 * n_robots)
    tasks = []
    for i in range(n_tasks):
        zone = rng.randrange(n_zones)
        duration = {r.name: float(rng.randint(*MINUTES)) for r in robots}
        after: tuple[str, ...] = ()
        if i and rng.random() < SHARE_AFTER:
            window = range(max(0, i - WINDOW), i)
            picked = rng.sample(window, min(len(window), rng.choice((1, 2))))
            after = tuple(f"t{p + 1}" for p in sorted(picked))
        released = rng.random() < SHARE_RELEASED
        tasks.append(
            Task(
                id=f"t{i + 1}",
                name=f"task {i + 1} in {zone_name(zone)}",
                features=(FEATURE,),
                duration=duration,
                after=after,
                zone=zone_name(zone),
                release=float(rng.randint(0, release_until)) if released else None,
            )
        )
    travel = {
        zone_name(a): {zone_name(b): float(way[a][b]) for b in range(a + 1, n_zones)}
        for a in range(n_zones)
    }
    return Instance(tasks=tuple(tasks), robots=robots, travel=travel)
