"""Small timed instances for the schedule tests, built by hand so every number is visible."""

from __future__ import annotations

from typing import Any

from app.domain.models import Instance, Robot, Task

RATES = {"x": 0.9}


def task(i: int | str, **time: Any) -> Task:
    return Task(id=i, name=f"t{i}", features=("x",), **time)


def robot(name: str, rate: float = 0.9, **time: Any) -> Robot:
    return Robot(name=name, success={"x": rate}, **time)


def two_zone_site() -> Instance:
    """Three tasks, two robots, zones A and B 4 minutes apart.

    t1 (A, 5 min) -> t2 (B, 3 min, only robot r); t3 (B, 4 min, released at 2)."""
    return Instance(
        tasks=(
            task(1, duration=5, zone="A"),
            task(2, duration={"r": 3}, after=(1,), zone="B"),
            task(3, duration=4, zone="B", release=2),
        ),
        robots=(robot("r", zone="A"), robot("s", 0.5, zone="B")),
        travel={"A": {"B": 4}},
    )
