"""Every bad timed input of docs/api.md#plans-in-time is a 422 naming the field and the task, never
a 5xx: through POST /allocate, and through POST /runs (whose instance part is the same schema) on
SQLite and PostgreSQL, where nothing may be stored."""

from __future__ import annotations

import copy
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.allocation.test_api_timed import ROBOTS, TASKS, TRAVEL, timed


def with_task(i: int, **changes: Any) -> list[dict[str, Any]]:
    """TASKS with task i changed; a None value removes the key."""
    tasks = copy.deepcopy(TASKS)
    for key, value in changes.items():
        if value is None:
            tasks[i].pop(key, None)
        else:
            tasks[i][key] = value
    return tasks


def with_robot(i: int, **changes: Any) -> list[dict[str, Any]]:
    robots = copy.deepcopy(ROBOTS)
    robots[i].update(changes)
    return robots


# (case, changes to the timed body, loc, words the message must hold: the task named)
INSTANCE_CASES: list[tuple[str, dict[str, Any], list[Any], list[str]]] = [
    (
        "precedence_cycle",
        {"tasks": with_task(0, after=["check"])},  # dig -> frame -> wire -> check -> dig
        ["body", "tasks", 2, "after"],  # an `after` on the cycle, which it writes out
        ["cycle", "'dig'", "'check'"],
    ),
    (
        "unknown_after",
        {"tasks": with_task(3, after=["frame", "nope"])},
        ["body", "tasks", 3, "after", 1],
        ["'paint'", "'nope'"],
    ),
    (
        "missing_duration",
        {"tasks": with_task(4, duration=None)},
        ["body", "tasks", 4, "duration"],
        ["'lift'", "no duration"],
    ),
    (
        "missing_travel_pair",
        {"travel": {"A": {"B": 3}}},  # nothing to or from C
        ["body", "travel", "A", "C"],
        ["'dig'", "'paint'"],
    ),
    (
        "impossible_deadline",  # dig, frame, wire, check: 20 + 15 + 12 + 8 at the shortest
        {"tasks": with_task(5, deadline=50)},
        ["body", "tasks", 5, "deadline"],
        ["'check'", "'dig'", "55"],
    ),
    (
        "shift_too_short",
        {"robots": [with_robot(0, available=[0, 15])[0], with_robot(1, available=[10, 25])[1]]},
        ["body", "tasks", 0, "duration"],
        ["'dig'", "shift"],
    ),
    (
        "duration_map_names_an_unknown_robot",
        {"tasks": with_task(0, duration={"a": 20, "zz": 5})},
        ["body", "tasks", 0, "duration", "zz"],
        ["'dig'", "'zz'"],
    ),
    (
        "zone_missing_on_one_task",
        {"tasks": with_task(2, zone=None)},
        ["body", "tasks", 2, "zone"],
        ["'wire'"],
    ),
    (
        "shift_ends_before_it_starts",
        {"robots": with_robot(1, available=[100, 50])},
        ["body", "robots", 1, "available"],
        ["'b'"],
    ),
    ("negative_duration", {"tasks": with_task(1, duration=-5)},
     ["body", "tasks", 1, "duration"], []),
    ("zero_duration", {"tasks": with_task(1, duration=0)}, ["body", "tasks", 1, "duration"], []),
    ("empty_duration_map", {"tasks": with_task(1, duration={})},
     ["body", "tasks", 1, "duration"], ["at least one robot"]),
    ("duration_text", {"tasks": with_task(1, duration="15")}, ["body", "tasks", 1, "duration"], []),
    (
        "release_too_large",
        {"tasks": with_task(3, release=1e12)},
        ["body", "tasks", 3, "release"],
        [],
    ),
    ("travel_negative", {"travel": {"A": {"B": -3}}}, ["body", "travel", "A", "B"], []),
    ("start_without_offset", {"start": "2026-03-02T07:00:00"}, ["body", "start"], ["offset"]),
    ("start_not_a_time", {"start": 1740000000}, ["body", "start"], []),
]  # fmt: skip

ALLOCATE_CASES: list[tuple[str, dict[str, Any], list[Any], list[str]]] = [
    *INSTANCE_CASES,
    ("time_limit_zero", {"options": {"time_limit_s": 0}}, ["body", "options", "time_limit_s"], []),
    (
        "time_limit_above_120",
        {"options": {"time_limit_s": 121}},
        ["body", "options", "time_limit_s"],
        ["120"],
    ),
    (
        "time_limit_text",
        {"options": {"time_limit_s": "fast"}},
        ["body", "options", "time_limit_s"],
        [],
    ),
    ("unknown_objective", {"objective": "cheapest"}, ["body", "objective"], []),
    (
        "floor_without_makespan",
        {"min_expected_success": 0.5},
        ["body", "min_expected_success"],
        ["makespan"],
    ),
    (
        "travel_with_a_scenario",
        {"tasks": None, "robots": None, "start": None, "scenario": "baseline"},
        ["body", "travel"],
        ["scenario"],
    ),
    (
        "pin_start_on_an_unknown_task",
        {"pinned": [{"task_id": "nope", "robot": "a", "start": 5}]},
        ["body", "pinned", 0, "task_id"],
        ["'nope'"],
    ),
]  # fmt: skip


def _body(changes: dict[str, Any]) -> dict[str, Any]:
    body = timed()
    for key, value in changes.items():
        if value is None:
            body.pop(key, None)
        else:
            body[key] = value
    return body


def _assert_names(response: Any, loc: list[Any], words: list[str]) -> None:
    assert response.status_code == 422, response.text
    detail = response.json()["detail"]
    assert detail[0]["loc"] == loc, detail
    for word in words:
        assert word in detail[0]["msg"], detail[0]["msg"]


@pytest.mark.parametrize(
    ("changes", "loc", "words"),
    [case[1:] for case in ALLOCATE_CASES],
    ids=[case[0] for case in ALLOCATE_CASES],
)
def test_bad_timed_input_to_allocate_is_a_422_naming_field_and_task(
    client: TestClient, changes: dict[str, Any], loc: list[Any], words: list[str]
) -> None:
    # The instance's rules hold whichever method is asked; options are the solver's own.
    for solver in ("schedule",) if "options" in changes else ("schedule", "greedy"):
        _assert_names(
            client.post("/allocate", json={**_body(changes), "solver": solver}), loc, words
        )


UNTIMED = {"solver": "dp", "scenario": "baseline"}


@pytest.mark.parametrize(
    ("extra", "loc"),
    [
        ({"objective": "makespan"}, ["body", "objective"]),
        (
            {
                "tasks": [{"id": 1, "features": ["heavy"]}],
                "robots": [{"name": "a", "success": {"heavy": 0.9}}],
                "scenario": None,
                "pinned": [{"task_id": 1, "robot": "a", "start": 5}],
            },
            ["body", "pinned", 0, "start"],
        ),
        (
            {
                "tasks": [{"id": 1, "features": ["heavy"], "zone": "A"}],
                "robots": [{"name": "a", "success": {"heavy": 0.9}}],
                "scenario": None,
            },
            ["body", "tasks", 0, "zone"],
        ),
    ],
    ids=["objective", "pinned_start", "zone_without_durations"],
)
def test_time_fields_on_an_untimed_instance_are_a_422(
    client: TestClient, extra: dict[str, Any], loc: list[Any]
) -> None:
    body = {k: v for k, v in {**UNTIMED, **extra}.items() if v is not None}
    _assert_names(client.post("/allocate", json=body), loc, [])


# The rules that need no travel: the same site without zones (wiring a run's travel and
# start is the run service's part, tested with the runs).
ZONELESS_TASKS = [{k: v for k, v in t.items() if k != "zone"} for t in TASKS]
ZONELESS_ROBOTS = [{k: v for k, v in r.items() if k != "zone"} for r in ROBOTS]
RUN_CASES: list[tuple[str, list[dict[str, Any]], list[dict[str, Any]], list[Any], str]] = [
    ("cycle", [{**ZONELESS_TASKS[0], "after": ["check"]}, *ZONELESS_TASKS[1:]], ZONELESS_ROBOTS,
     ["body", "tasks", 2, "after"], "'check' -> 'dig'"),
    ("unknown_after", [*ZONELESS_TASKS[:3], {**ZONELESS_TASKS[3], "after": ["nope"]},
                       *ZONELESS_TASKS[4:]], ZONELESS_ROBOTS,
     ["body", "tasks", 3, "after", 0], "'nope'"),
    ("missing_duration", [*ZONELESS_TASKS[:4], {"id": "lift", "features": ["heavy"]},
                          ZONELESS_TASKS[5]], ZONELESS_ROBOTS,
     ["body", "tasks", 4, "duration"], "'lift'"),
    ("missing_travel", TASKS, ROBOTS, ["body", "travel", "A", "B"], "'dig'"),
    ("impossible_deadline", [*ZONELESS_TASKS[:5], {**ZONELESS_TASKS[5], "deadline": 50}],
     ZONELESS_ROBOTS, ["body", "tasks", 5, "deadline"], "'check'"),
    ("shift_too_short", ZONELESS_TASKS,
     [{**ZONELESS_ROBOTS[0], "available": [0, 15]}, {**ZONELESS_ROBOTS[1], "available": [10, 25]}],
     ["body", "tasks", 0, "duration"], "'dig'"),
    ("negative_duration", [{**ZONELESS_TASKS[0], "duration": -1}, *ZONELESS_TASKS[1:]],
     ZONELESS_ROBOTS, ["body", "tasks", 0, "duration"], ""),
]  # fmt: skip


@pytest.mark.parametrize(
    ("tasks", "robots", "loc", "word"),
    [case[1:] for case in RUN_CASES],
    ids=[case[0] for case in RUN_CASES],
)
def test_bad_timed_input_to_runs_is_a_422_and_stores_nothing(
    any_db_client: TestClient,
    tasks: list[dict[str, Any]],
    robots: list[dict[str, Any]],
    loc: list[Any],
    word: str,
) -> None:
    body = {"tasks": tasks, "robots": robots, "reasoner": "rules"}
    response = any_db_client.post("/runs", json=body)
    _assert_names(response, loc, [word] if word else [])
    assert any_db_client.get("/runs").json() == []  # nothing half-written


def test_the_timed_site_is_valid_as_sent() -> None:
    # The cases above each break one rule of a body that is otherwise fine.
    assert TRAVEL and len(TASKS) == 6
