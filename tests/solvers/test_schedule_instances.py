"""Timed instances (docs/schedules.md#the-model): what they accept, what they refuse and how they
say it."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

import numpy as np
import pytest

from app.domain.catalog import scenario, scenarios
from app.domain.errors import DomainError
from app.domain.models import Instance
from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem
from app.domain.serialize import instance_from_dict, instance_to_dict
from app.solvers.registry import get_solver
from tests.support.timed_support import robot, task, two_zone_site


def test_untimed_instances_are_what_they_were() -> None:
    for sc in scenarios().values():
        inst = sc.instance
        assert not inst.timed
        assert inst.eligible.all() and inst.eligible.shape == (36, 3)
        data = instance_to_dict(inst)
        assert list(data) == ["tasks", "robots"]
        assert list(data["tasks"][0]) == ["id", "name", "type", "features"]
        assert list(data["robots"][0]) == ["name", "label", "description", "success"]
        assert instance_from_dict(data) == inst
    with pytest.raises(ValueError, match="untimed"):
        _ = scenario("baseline").instance.timing


def test_a_timed_instance_has_its_index_view() -> None:
    inst = two_zone_site()
    tm = inst.timing
    assert inst.timed
    assert tm.durations == ((5.0, 5.0), (3.0, None), (4.0, 4.0))
    assert inst.eligible.tolist() == [[True, True], [True, False], [True, True]]
    assert tm.predecessors == ((), (0,), ())
    assert tm.zones == ("A", "B") and tm.task_zone == (0, 1, 1) and tm.robot_zone == (0, 1)
    # Given one way, travel holds both ways; 0 inside a zone.
    assert tm.travel_minutes == ((0.0, 4.0), (4.0, 0.0))
    assert tm.release == (0.0, 0.0, 2.0) and tm.deadline == (np.inf,) * 3
    assert tm.shifts == ((0.0, np.inf), (0.0, np.inf))
    assert tm.earliest_finish == (5.0, 8.0, 6.0)


def test_travel_takes_the_quickest_route() -> None:
    inst = Instance(
        tasks=(task(1, duration=1, zone="A"), task(2, duration=1, zone="C")),
        robots=(robot("r", zone="B"),),
        travel={"A": {"B": 2, "C": 20}, "C": {"B": 3}},
    )
    zones = inst.timing.zones
    a, c = zones.index("A"), zones.index("C")
    assert inst.timing.travel_minutes[a][c] == 5  # through B, not the 20 of the entry


def test_a_timed_instance_round_trips_through_its_stored_form() -> None:
    inst = Instance(
        tasks=(
            task(1, duration={"r": 5, "s": 7}, zone="A", release=3, deadline=90),
            task("b", duration=2.5, zone="B", after=(1,)),
        ),
        robots=(robot("r", zone="A", available=(0, 480)), robot("s")),
        travel={"A": {"B": 6}},
        start=datetime(2026, 3, 2, 7, 0, tzinfo=UTC),
    )
    again = instance_from_dict(instance_to_dict(inst))
    assert again == inst and again.timing == inst.timing


def _site(**changes: Any) -> dict[str, Any]:
    """A valid timed instance as keyword arguments, with `changes` applied to it."""
    base: dict[str, Any] = {
        "tasks": [
            {"id": 0, "duration": 10, "zone": "A"},
            {"id": 1, "duration": {"r": 5, "s": 9}, "zone": "B", "after": (0,)},
            {"id": 2, "duration": 4, "zone": "B"},
        ],
        "robots": [{"name": "r", "zone": "A"}, {"name": "s", "available": (0, 100)}],
        "travel": {"A": {"B": 4}},
    }
    for key, value in changes.items():
        kind, index, field = key.split("__")
        base[kind][int(index)][field] = value
    return base


def _build(spec: dict[str, Any]) -> Instance:
    tasks = tuple(
        task(t.pop("id"), **{k: v for k, v in t.items() if v is not None})
        for t in (dict(x) for x in spec["tasks"])
    )
    robots = tuple(robot(r.pop("name"), **r) for r in (dict(x) for x in spec["robots"]))
    return Instance(tasks=tasks, robots=robots, travel=spec.get("travel"), start=spec.get("start"))


def test_the_helper_site_is_valid() -> None:
    assert _build(_site()).timed


@pytest.mark.parametrize(
    ("spec", "field", "words"),
    [
        (_site(tasks__2__duration=None), "tasks.2.duration", ["task 2", "every task needs one"]),
        (_site(tasks__0__after=(7,)), "tasks.0.after.0", ["unknown task id 7"]),
        (_site(tasks__0__after=(1,)), "tasks.0.after", ["precedence cycle", "1 -> 0 -> 1"]),
        (_site(tasks__2__after=(2,)), "tasks.2.after", ["precedence cycle", "2 -> 2"]),
        (_site(tasks__2__zone="C"), "travel.A.C", ["'A' and 'C'", "task 2", "add"]),
        (_site(tasks__2__zone=None), "tasks.2.zone", ["task 2", "every task needs one"]),
        (_site(tasks__2__duration=0), "tasks.2.duration", ["positive number of minutes"]),
        (_site(tasks__2__duration={"q": 3}), "tasks.2.duration.q", ["unknown robot 'q'"]),
        (_site(tasks__2__duration={}), "tasks.2.duration", ["names no robot"]),
        (_site(tasks__2__release=-1), "tasks.2.release", ["non-negative"]),
        (
            _site(tasks__2__release=10, tasks__2__deadline=12),
            "tasks.2.deadline",
            ["task 2", "deadline (minute 12)", "end at minute 14"],
        ),
        (
            # the chain: 0 takes 10, then 1 takes 5 at the shortest: 15 > 14
            _site(tasks__1__deadline=14),
            "tasks.1.deadline",
            ["task 1", "0 (10 min", "then 1 (5 min", "minute 15"],
        ),
        (
            _site(robots__1__available=(0, 3), tasks__2__duration={"s": 4}),
            "tasks.2.duration",
            ["no robot can fit task 2", "'s' takes 4 min, shift [0, 3]"],
        ),
        (_site(robots__1__available=(50, 20)), "robots.1.available", ["ends (20) before"]),
        (_site(robots__1__zone="Z"), "travel.A.Z", ["robot 's' starts in 'Z'"]),
    ],
)
def test_bad_timed_input_names_the_field_and_the_task(
    spec: dict[str, Any], field: str, words: list[str]
) -> None:
    with pytest.raises(DomainError) as err:
        _build(spec)
    assert err.value.field == field
    for word in words:
        assert word in err.value.message, err.value.message


def test_time_fields_need_durations() -> None:
    with pytest.raises(DomainError) as err:
        Instance(tasks=(task(1, zone="A"),), robots=(robot("r"),))
    assert err.value.field == "tasks.0.zone" and "give every task a 'duration'" in err.value.message
    with pytest.raises(DomainError) as err:
        Instance(tasks=(task(1),), robots=(robot("r", available=(0, 9)),))
    assert err.value.field == "robots.0.available"


def test_start_needs_an_offset_and_zones_need_tasks_with_zones() -> None:
    with pytest.raises(DomainError) as err:
        Instance(tasks=(task(1, duration=1),), robots=(robot("r"),), start=datetime(2026, 1, 1))
    assert err.value.field == "start" and "UTC offset" in err.value.message
    with pytest.raises(DomainError) as err:
        Instance(tasks=(task(1, duration=1),), robots=(robot("r", zone="A"),))
    assert err.value.field == "robots.0.zone"
    with pytest.raises(DomainError) as err:
        Instance(
            tasks=(task(1, duration=1, zone="A"),),
            robots=(robot("r"),),
            travel={"A": {"A": 3}},
        )
    assert err.value.field == "travel.A.A"


def test_problem_time_arguments_are_checked() -> None:
    inst = two_zone_site()
    with pytest.raises(DomainError) as err:
        Problem.build(inst, Mode.SUCCESS_FOCUSED, pinned={1: 1})
    assert err.value.field == "pinned" and "cannot take it" in err.value.message
    with pytest.raises(DomainError) as err:
        Problem.build(inst, Mode.SUCCESS_FOCUSED, unavailable=[0])
    assert err.value.field == "unavailable" and "task 2" in err.value.message
    with pytest.raises(DomainError) as err:
        Problem.build(inst, Mode.SUCCESS_FOCUSED, pinned_starts={0: 3})
    assert err.value.field == "pinned_starts" and "no pin" in err.value.message
    untimed = scenario("baseline").instance
    with pytest.raises(DomainError) as err:
        Problem.build(untimed, objective=Objective(ObjectiveKind.MAKESPAN))
    assert err.value.field == "objective"
    with pytest.raises(DomainError) as err:
        Problem.build(untimed, not_before=5)
    assert err.value.field == "not_before"


@pytest.mark.parametrize(
    ("kind", "floor", "field"),
    [
        ("fastest", 0.0, "objective"),
        ("makespan", 1.5, "min_expected_success"),
        ("success_then_makespan", 0.5, "min_expected_success"),
    ],
)
def test_bad_objectives(kind: str, floor: float, field: str) -> None:
    with pytest.raises(DomainError) as err:
        Objective(kind, floor)  # type: ignore[arg-type]
    assert err.value.field == field


def test_optimal_keeps_tasks_off_robots_that_cannot_take_them() -> None:
    inst = Instance(
        tasks=tuple(task(i, duration={"weak": 5} if i == 0 else 5) for i in range(4)),
        robots=(robot("strong", 0.9), robot("weak", 0.4)),
    )
    problem = Problem.build(inst, Mode.SUCCESS_FOCUSED)
    assert get_solver("optimal").solve(problem).assignment == [1, 0, 0, 0]
    assert get_solver("greedy").solve(problem).assignment == [1, 0, 0, 0]
