"""Seeded timed construction instances (docs/schedules.md#the-generator): floors x zones x trades.

A building of `floors` floors, each split into `zones_per_floor` zones; each zone holds
work packages, and each package is one trade chain: formwork -> rebar -> pour ->
inspection (the inspection checks the work before it). A floor's formwork waits for the
pour of the same zone on the floor below (the slab it stands on). Concrete arrives in
deliveries: a pour on floor f is released at minute `delivery_every * f`. Robots are
light, medium and heavy in turn, with the paper's baseline rates jittered by +-0.05;
a robot's minutes on a task follow the same rule as the timed paper scenario (base
minutes of the trade x mean over its features of 0.9 / rate), jittered by +-20%.
Travel: 2 minutes to change zones plus 3 per zone along the floor plus 4 per floor (the
hoist). Robots start on the ground floor, spread over its zones; every third robot
starts its shift 30 minutes late. Queue order is floor, zone, package, trade (each task
after the tasks it waits for), so any prefix is a valid instance: `n_tasks` cuts there.

Sizes used by the tests and the benchmark: 36 tasks x 3 robots, 200 x 20, 1,000 x 20.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

from app.domain.models import Instance, Robot, Task

REFERENCE_RATE = 0.9


@dataclass(frozen=True)
class Trade:
    name: str
    features: tuple[str, ...]
    base_minutes: int


TRADES = (
    Trade("formwork", ("heavy", "careful"), 40),
    Trade("rebar", ("heavy", "dexterous"), 35),
    Trade("pour", ("heavy",), 25),
    Trade("inspection", ("careful", "dexterous"), 15),
)
KINDS = {
    "light": {"careful": 0.9, "dexterous": 0.8, "heavy": 0.5},
    "medium": {"careful": 0.7, "dexterous": 0.6, "heavy": 0.7},
    "heavy": {"careful": 0.5, "dexterous": 0.4, "heavy": 0.9},
}


@dataclass(frozen=True)
class Layout:
    floors: int
    zones_per_floor: int
    packages_per_zone: int

    @classmethod
    def for_tasks(cls, n_tasks: int) -> Layout:
        packages = math.ceil(n_tasks / len(TRADES))
        zones = 3 if packages <= 9 else 5
        floors = min(10, math.ceil(packages / zones))
        return cls(floors, zones, math.ceil(packages / (floors * zones)))


def zone_name(floor: int, zone: int) -> str:
    return f"F{floor}{chr(ord('A') + zone)}"


def travel_matrix(layout: Layout) -> dict[str, dict[str, float]]:
    names = [(f, z) for f in range(layout.floors) for z in range(layout.zones_per_floor)]
    out: dict[str, dict[str, float]] = {}
    for i, (f1, z1) in enumerate(names):
        row = out.setdefault(zone_name(f1, z1), {})
        for f2, z2 in names[i + 1 :]:
            row[zone_name(f2, z2)] = 2 + 3 * abs(z1 - z2) + 4 * abs(f1 - f2)
    return out


def construction_site(
    n_tasks: int,
    n_robots: int,
    *,
    seed: int = 0,
    delivery_every: int = 60,
    light_pours: bool = True,
    zones: tuple[int, int] | None = None,
    minutes_scale: float = 1.0,
) -> Instance:
    """A timed instance of `n_tasks` tasks and `n_robots` robots. `light_pours=False`
    leaves light robots out of the pours' duration maps (they cannot take them). `zones`
    = (floors, zones per floor) fixes the layout (default: by size); (2, 2) is a site of
    4 zones with travel of 2-9 minutes between them. `minutes_scale` scales the trades'
    base minutes (0.125: tasks of about 7 minutes, as long as the travel)."""
    rng = random.Random(seed)
    layout = Layout.for_tasks(n_tasks)
    if zones is not None:
        packages = math.ceil(n_tasks / len(TRADES))
        layout = Layout(zones[0], zones[1], math.ceil(packages / (zones[0] * zones[1])))
    robots = tuple(_robot(i, rng, layout) for i in range(n_robots))
    tasks: list[Task] = []
    pour_below: dict[tuple[int, int, int], str] = {}
    for f in range(layout.floors):
        for z in range(layout.zones_per_floor):
            for p in range(layout.packages_per_zone):
                previous: str | None = pour_below.get((f - 1, z, p))
                for trade in TRADES:
                    task_id = f"F{f}{chr(ord('A') + z)}-{p}-{trade.name}"
                    tasks.append(
                        Task(
                            id=task_id,
                            name=f"{trade.name} {zone_name(f, z)} #{p}",
                            features=trade.features,
                            type=trade.name,
                            duration=_durations(trade, robots, rng, light_pours, minutes_scale),
                            after=() if previous is None else (previous,),
                            zone=zone_name(f, z),
                            release=delivery_every * f if trade.name == "pour" and f else None,
                        )
                    )
                    if trade.name == "pour":
                        pour_below[(f, z, p)] = task_id
                    previous = task_id
    kept = tasks[:n_tasks]
    return Instance(tasks=tuple(kept), robots=robots, travel=travel_matrix(layout))


def _robot(i: int, rng: random.Random, layout: Layout) -> Robot:
    kind = list(KINDS)[i % len(KINDS)]
    rates = {
        f: round(min(0.99, max(0.05, p + rng.uniform(-0.05, 0.05))), 2)
        for f, p in KINDS[kind].items()
    }
    late = 30 if i % 3 == 2 else 0
    return Robot(
        name=f"{kind}-{i}",
        success=rates,
        label=f"{kind.title()} Robot {i}",
        zone=zone_name(0, i % layout.zones_per_floor),
        available=(late, late + 7 * 24 * 60),
    )


def _durations(
    trade: Trade,
    robots: tuple[Robot, ...],
    rng: random.Random,
    light_pours: bool,
    minutes_scale: float = 1.0,
) -> dict[str, float]:
    out: dict[str, float] = {}
    for robot in robots:
        if trade.name == "pour" and not light_pours and robot.name.startswith("light"):
            continue
        pace = sum(REFERENCE_RATE / robot.success[f] for f in trade.features) / len(trade.features)
        minutes = trade.base_minutes * minutes_scale * pace * rng.uniform(0.8, 1.2)
        out[robot.name] = max(1, round(minutes))
    return out
