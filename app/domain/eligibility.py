"""Which robot may take which task, and the time arguments of a Problem, checked.

The rule itself is `Instance.eligible` (docs/allocation.md#teams): a robot's `skills`, and a
per-robot duration map that omits a robot (docs/schedules.md#the-model). On top of the
instance's own rules, a problem's pins and unavailable robots must leave every task a robot
that may take it; a pinned start belongs to a pinned task; a team task is pinned only with its
whole team (a revision's pins).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping

from app.domain.errors import DomainError
from app.domain.models import Instance
from app.domain.objective import Objective


def check_time_arguments(
    instance: Instance,
    pins: Mapping[int, int],
    unavailable: frozenset[int],
    objective: Objective,
    starts: dict[int, float],
    not_before: float,
    teams: Collection[int] = frozenset(),
) -> dict[int, float]:
    """The pinned starts as floats; DomainError for anything that needs a timed instance
    without one, a pin on a robot that cannot take its task, or a task left without any
    available robot that can take it."""
    if not instance.timed:
        check_pins_eligible(instance, pins, unavailable, teams)
        for name, given in (
            ("objective", not objective.is_default),
            ("pinned_starts", bool(starts)),
            ("not_before", bool(not_before)),
        ):
            if given:
                raise DomainError(
                    name, "applies to timed instances only: give every task a 'duration'"
                )
        return {}
    if not (isinstance(not_before, int | float) and math.isfinite(not_before) and not_before >= 0):
        raise DomainError(
            "not_before", f"must be a non-negative number of minutes, got {not_before!r}"
        )
    check_pins_eligible(instance, pins, unavailable, teams)
    tasks = instance.tasks
    out: dict[int, float] = {}
    for t, start in sorted(starts.items()):
        if t not in pins:
            raise DomainError(
                "pinned_starts",
                f"task index {t} has a fixed start but no pin; a start belongs to a pinned task",
            )
        ok = isinstance(start, int | float) and math.isfinite(start) and start >= 0
        if not ok:
            raise DomainError(
                "pinned_starts",
                f"task {tasks[t].id!r}: a start is a non-negative number of minutes, got {start!r}",
            )
        out[t] = float(start)
    return out


def check_pins_eligible(
    instance: Instance,
    pins: Mapping[int, int],
    unavailable: frozenset[int],
    teams: Collection[int] = frozenset(),
) -> None:
    """A pin names a robot that may take its task, a team task is pinned only with its whole
    team (`teams`: a revision's, docs/living-plans.md#teams-in-a-revision), and every free task
    keeps an available robot that may take it."""
    tasks, robots = instance.tasks, instance.robots
    for t in pins:
        if tasks[t].team is not None and t not in teams:
            raise DomainError(
                "pinned",
                f"task {tasks[t].id!r} is a team task: pin it with its whole team "
                "(docs/living-plans.md#pins-in-allocate), or leave it free",
                code="team_pin",
            )
    eligible = instance.eligible
    if eligible.all():
        return
    why = "its duration map does not name that robot" if instance.timed else "its skills lack"
    for t, r in pins.items():
        if not eligible[t, r] and t not in teams:  # a pinned team is what was decided
            reason = why if instance.timed else f"{why} a feature the task needs"
            raise DomainError(
                "pinned",
                f"task {tasks[t].id!r} is pinned on robot '{robots[r].name}', which cannot take "
                f"it: {reason}",
                code="ineligible_pin",
            )
    for t in range(instance.n_tasks):
        if t in pins:
            continue
        if not any(eligible[t, r] and r not in unavailable for r in range(instance.n_robots)):
            names = ", ".join(robots[r].name for r in range(instance.n_robots) if eligible[t, r])
            raise DomainError(
                "unavailable",
                f"task {tasks[t].id!r} ({tasks[t].name}) can be taken only by {names}, and none "
                "of them is available; make one available or pin the task",
                code="no_robot_left",
            )
