"""Every malformed request gets a 4xx whose body is {"detail": [{"loc", "msg", "type"}]}
and whose `loc` (or message) names the offending field — never a 5xx."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient

ROBOTS: list[dict[str, Any]] = [
    {"name": "a", "success": {"heavy": 0.9, "dexterous": 0.2, "careful": 0.5}},
    {"name": "b", "success": {"heavy": 0.3, "dexterous": 0.8, "careful": 0.7}},
]
TASKS: list[dict[str, Any]] = [
    {"id": 1, "name": "Lift", "features": ["heavy"]},
    {"id": 2, "name": "Sand", "features": ["dexterous"]},
    {"id": 3, "name": "Pour", "features": ["careful", "heavy"]},
]


def custom(**changes: Any) -> dict[str, Any]:
    """A valid custom-instance body (deep-copied) with top-level changes; None deletes a key."""
    body: dict[str, Any] = json.loads(
        json.dumps({"solver": "dp", "tasks": TASKS, "robots": ROBOTS})
    )
    for key, value in changes.items():
        if value is None:
            body.pop(key, None)
        else:
            body[key] = value
    return body


def task(**changes: Any) -> list[dict[str, Any]]:
    """TASKS with the first task changed."""
    return [{**TASKS[0], **changes}, *TASKS[1:]]


def robot(**changes: Any) -> list[dict[str, Any]]:
    """ROBOTS with the first robot changed."""
    return [{**ROBOTS[0], **changes}, *ROBOTS[1:]]


def rates(**changes: Any) -> list[dict[str, Any]]:
    return robot(success={**ROBOTS[0]["success"], **changes})


def base(**changes: Any) -> dict[str, Any]:
    return {"solver": "dp", "scenario": "baseline", **changes}


def many_tasks(n: int) -> list[dict[str, Any]]:
    return [{"id": i, "features": ["heavy"]} for i in range(n)]


# (case id, JSON body, expected status, expected loc, substring of some msg or None)
CASES: list[tuple[str, Any, int, list[Any], str | None]] = [
    ("unknown_solver", base(solver="simplex"), 422, ["body", "solver"], "simplex"),
    ("missing_solver", {"scenario": "baseline"}, 422, ["body", "solver"], None),
    ("solver_not_string", base(solver=7), 422, ["body", "solver"], None),
    ("unknown_mode", base(mode="careless"), 422, ["body", "mode"], "balanced"),
    ("mode_not_string", base(mode=2), 422, ["body", "mode"], None),
    ("unknown_scenario", base(scenario="mars"), 422, ["body", "scenario"], "mars"),
    ("scenario_and_tasks", custom(scenario="baseline"), 422, ["body", "scenario"], "not both"),
    ("no_instance", {"solver": "dp"}, 422, ["body", "scenario"], "tasks"),
    ("tasks_without_robots", custom(robots=None), 422, ["body", "robots"], "robots missing"),
    ("robots_without_tasks", custom(tasks=None), 422, ["body", "tasks"], "tasks missing"),
    ("empty_tasks", custom(tasks=[]), 422, ["body", "tasks"], "empty"),
    ("empty_robots", custom(robots=[]), 422, ["body", "robots"], "empty"),
    ("tasks_not_list", custom(tasks={"id": 1}), 422, ["body", "tasks"], None),
    ("robots_not_list", custom(robots="a,b"), 422, ["body", "robots"], None),
    ("task_not_object", custom(tasks=["Lift"]), 422, ["body", "tasks", 0], None),
    (
        "duplicate_task_ids",
        custom(tasks=[*TASKS, {"id": 2, "features": ["heavy"]}]),
        422,
        ["body", "tasks", 3, "id"],
        "duplicate",
    ),
    (
        "duplicate_ids_int_and_str",
        custom(tasks=[*TASKS, {"action_id": "1", "features": ["heavy"]}]),
        422,
        ["body", "tasks", 3, "id"],
        "duplicate",
    ),
    (
        "missing_task_id",
        custom(tasks=[{"name": "x", "features": ["heavy"]}]),
        422,
        ["body", "tasks", 0, "id"],
        None,
    ),
    ("task_id_float", custom(tasks=task(id=1.5)), 422, ["body", "tasks", 0, "id"], "integer"),
    ("task_id_bool", custom(tasks=task(id=True)), 422, ["body", "tasks", 0, "id"], "boolean"),
    (
        "task_id_too_long",
        custom(tasks=task(id="x" * 201)),
        422,
        ["body", "tasks", 0, "id"],
        "at most 200 characters",
    ),
    (
        "task_id_int_too_long",
        custom(tasks=task(id=10**201)),
        422,
        ["body", "tasks", 0, "id"],
        "at most 200 characters",
    ),
    (
        "unknown_feature",
        custom(tasks=task(features=["welding"])),
        422,
        ["body", "tasks", 0, "features"],
        "welding",
    ),
    (
        "empty_features",
        custom(tasks=task(features=[])),
        422,
        ["body", "tasks", 0, "features"],
        None,
    ),
    (
        "features_not_list",
        custom(tasks=task(features="heavy")),
        422,
        ["body", "tasks", 0, "features"],
        None,
    ),
    (
        "feature_not_string",
        custom(tasks=task(features=["heavy", 3])),
        422,
        ["body", "tasks", 0, "features", 1],
        None,
    ),
    (
        "probability_negative",
        custom(robots=rates(heavy=-0.1)),
        422,
        ["body", "robots", 0, "success", "heavy"],
        None,
    ),
    (
        "probability_above_one",
        custom(robots=rates(heavy=1.2)),
        422,
        ["body", "robots", 0, "success", "heavy"],
        None,
    ),
    (
        "probability_string",
        custom(robots=rates(heavy="0.9")),
        422,
        ["body", "robots", 0, "success", "heavy"],
        None,
    ),
    (
        "probability_bool",
        custom(robots=rates(heavy=True)),
        422,
        ["body", "robots", 0, "success", "heavy"],
        None,
    ),
    (
        "success_empty",
        custom(robots=robot(success={})),
        422,
        ["body", "robots", 0, "success"],
        None,
    ),
    (
        "success_not_object",
        custom(robots=robot(success=[0.9])),
        422,
        ["body", "robots", 0, "success"],
        None,
    ),
    (
        "feature_unrated_by_a_robot",
        custom(robots=robot(success={"heavy": 0.9})),
        422,
        ["body", "tasks", 1, "features"],
        "not rated by robot(s) a",
    ),
    (
        "duplicate_robot_names",
        custom(robots=[ROBOTS[0], ROBOTS[0]]),
        422,
        ["body", "robots", 1, "name"],
        "duplicate",
    ),
    (
        "duplicate_robot_names_by_case",
        custom(robots=[ROBOTS[0], {**ROBOTS[1], "name": "A"}]),
        422,
        ["body", "robots", 1, "name"],
        "duplicate",
    ),
    ("empty_robot_name", custom(robots=robot(name="")), 422, ["body", "robots", 0, "name"], None),
    (
        "robot_unknown_key",
        custom(robots=robot(succes={})),
        422,
        ["body", "robots", 0, "succes"],
        None,
    ),
    (
        "infeasible_cap",
        custom(max_deviation=0),
        422,
        ["body", "max_deviation"],
        "raise max_deviation",
    ),
    (
        "infeasible_fractional_cap",
        custom(
            tasks=many_tasks(7),
            robots=[*ROBOTS, {"name": "c", "success": {"heavy": 0.5}}],
            max_deviation=0.2,
        ),
        422,
        ["body", "max_deviation"],
        "at least 3 and at most 2",
    ),
    ("negative_max_deviation", base(max_deviation=-1), 422, ["body", "max_deviation"], None),
    ("max_deviation_string", base(max_deviation="4"), 422, ["body", "max_deviation"], None),
    ("too_many_tasks", custom(tasks=many_tasks(10_001)), 422, ["body", "tasks"], "10000"),
    (
        "too_many_robots",
        custom(
            robots=[{"name": f"r{i}", "success": {"heavy": 0.5}} for i in range(101)],
            tasks=many_tasks(3),
        ),
        422,
        ["body", "robots"],
        "100",
    ),
    (
        "brute_force_too_large",
        base(solver="brute_force"),
        422,
        ["body", "tasks"],
        "150,094,635,296,999,121",
    ),
    (
        "dp_too_large",
        custom(tasks=many_tasks(200), robots=[*ROBOTS, {"name": "c", "success": {"heavy": 0.5}}]),
        422,
        ["body", "tasks"],
        "dp would visit",
    ),
    ("seed_string", base(seed="1"), 422, ["body", "seed"], None),
    ("seed_negative", base(seed=-1), 422, ["body", "seed"], None),
    ("seed_float", base(seed=1.5), 422, ["body", "seed"], None),
    ("unknown_option", base(options={"bogus": 1}), 422, ["body", "options", "bogus"], "accepts"),
    ("options_not_object", base(options=[1]), 422, ["body", "options"], None),
    ("unknown_top_level_field", base(solvr="dp"), 422, ["body", "solvr"], None),
    ("non_object_body", [base()], 422, ["body"], None),
    ("null_body", None, 422, ["body"], None),
]


def assert_error_shape(body: Any) -> list[dict[str, Any]]:
    assert isinstance(body, dict) and set(body) == {"detail"}, body
    detail = body["detail"]
    assert isinstance(detail, list) and detail
    for item in detail:
        assert set(item) == {"loc", "msg", "type"}, item
        assert isinstance(item["loc"], list) and item["loc"]
        assert isinstance(item["msg"], str) and item["msg"]
        assert isinstance(item["type"], str) and item["type"]
    return detail


def assert_names(detail: list[dict[str, Any]], loc: list[Any], msg: str | None) -> None:
    matching = [d for d in detail if d["loc"][: len(loc)] == loc]
    assert matching, f"no error at {loc}: {detail}"
    if msg is not None:
        assert any(msg in d["msg"] for d in matching), detail


@pytest.mark.parametrize(
    ("body", "status", "loc", "msg"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_malformed_json_body(
    client: TestClient, body: Any, status: int, loc: list[Any], msg: str | None
) -> None:
    r = client.post("/allocate", json=body)
    assert r.status_code == status, r.text[:1000]
    assert_names(assert_error_shape(r.json()), loc, msg)


JSON = "application/json"
RAW_CASES = [
    ("malformed_json", '{"solver": "dp", "scenario": ', JSON, 422, "JSON decode error"),
    ("trailing_comma", '{"solver": "dp",}', JSON, 422, "JSON decode error"),
    (
        "nan_max_deviation",
        '{"solver": "dp", "scenario": "baseline", "max_deviation": NaN}',
        JSON,
        422,
        "finite",
    ),
    ("empty_body", "", JSON, 422, "required"),
    ("not_json_content_type", '{"solver": "dp", "scenario": "baseline"}', "text/plain", 422, None),
    (
        "unparseable_giant_integer",
        '{"solver": "dp", "scenario": "baseline", "seed": ' + "9" * 5000 + "}",
        JSON,
        400,
        "parsing the body",
    ),
]


@pytest.mark.parametrize(
    ("content", "content_type", "status", "msg"),
    [c[1:] for c in RAW_CASES],
    ids=[c[0] for c in RAW_CASES],
)
def test_malformed_raw_body(
    client: TestClient, content: str, content_type: str, status: int, msg: str | None
) -> None:
    r = client.post("/allocate", content=content, headers={"content-type": content_type})
    assert r.status_code == status, r.text
    detail = assert_error_shape(r.json())
    assert detail[0]["loc"][0] == "body"
    if msg is not None:
        assert msg in detail[0]["msg"]


def test_infeasible_cap_explains_why(client: TestClient) -> None:
    r = client.post("/allocate", json=custom(max_deviation=0))
    assert r.status_code == 422
    (item,) = assert_error_shape(r.json())
    assert item["type"] == "infeasible_cap"
    # W = 1.5: a robot would need at least 2 and at most 1 tasks.
    assert "target load 1.5" in item["msg"] and "at least 2 and at most 1" in item["msg"]


def test_oversized_body_is_413_by_content_length(make_client: Any) -> None:
    small = make_client(max_body_bytes=500)
    r = small.post("/allocate", json=custom(tasks=many_tasks(50)))
    assert r.status_code == 413
    (item,) = assert_error_shape(r.json())
    assert item["loc"] == ["body"] and "500 bytes" in item["msg"]
    assert small.post("/allocate", json=custom()).status_code == 200  # under the limit


def test_oversized_streamed_body_is_413(make_client: Any) -> None:
    small = make_client(max_body_bytes=500)

    def chunks() -> Iterator[bytes]:  # no Content-Length: counted while read
        yield b'{"solver": "dp", "tasks": ['
        for i in range(50):
            yield json.dumps({"id": i, "features": ["heavy"]}).encode() + b","
        yield b'{"id": -1, "features": ["heavy"]}], "robots": []}'

    r = small.post("/allocate", content=chunks(), headers={"content-type": "application/json"})
    assert r.status_code == 413
    assert assert_error_shape(r.json())[0]["loc"] == ["body"]


def test_unknown_route_is_404_in_the_same_shape(client: TestClient) -> None:
    r = client.get("/allocations")
    assert r.status_code == 404
    assert assert_error_shape(r.json())[0]["loc"] == ["path"]


def test_wrong_method_is_405_in_the_same_shape(client: TestClient) -> None:
    r = client.get("/allocate")
    assert r.status_code == 405
    assert assert_error_shape(r.json())[0]["loc"] == ["method"]
    assert "POST" in r.headers["allow"]


def test_unavailable_solver_is_a_4xx_not_a_crash(client: TestClient) -> None:
    from app.solvers import registry

    registry.register("missing_dep", "app.solvers.does_not_exist:Nothing")
    try:
        r = client.post("/allocate", json=base(solver="missing_dep"))
        listed = [s["name"] for s in client.get("/solvers").json()]
    finally:
        registry._SOLVERS.pop("missing_dep")
    assert r.status_code == 422
    (item,) = assert_error_shape(r.json())
    assert item["loc"] == ["body", "solver"] and "not available" in item["msg"]
    assert "missing_dep" not in listed


# -- size limits on every endpoint that reads a body ----------------------------------------
BODY_ENDPOINTS = ["/allocate", "/runs"]


def robots_rating_heavy(n: int) -> list[dict[str, Any]]:
    return [{"name": f"r{i}", "success": {"heavy": round(0.5 + i / 1000, 3)}} for i in range(n)]


@pytest.mark.parametrize("path", BODY_ENDPOINTS)
def test_over_long_body_with_content_length_is_413(make_client: Any, path: str) -> None:
    small = make_client(max_body_bytes=500)
    body = json.dumps(custom(tasks=many_tasks(50))).encode()
    r = small.post(path, content=body, headers={"content-type": JSON})
    assert r.status_code == 413, r.text
    (item,) = assert_error_shape(r.json())
    assert item["loc"] == ["body"] and item["type"] == "body_too_large"
    assert f"{len(body):,} bytes" in item["msg"] and "LTAA_MAX_BODY_BYTES" in item["msg"]


@pytest.mark.parametrize("path", BODY_ENDPOINTS)
def test_over_long_chunked_body_without_content_length_is_413(make_client: Any, path: str) -> None:
    small = make_client(max_body_bytes=500)

    def chunks() -> Iterator[bytes]:
        yield b'{"tasks": ['
        for i in range(50):
            yield b'{"id": %d, "features": ["heavy"]},' % i
        yield b'{"id": -1, "features": ["heavy"]}]}'

    r = small.post(path, content=chunks(), headers={"content-type": JSON})
    assert "content-length" not in r.request.headers  # streamed: counted while read
    assert r.status_code == 413, r.text
    (item,) = assert_error_shape(r.json())
    assert item["loc"] == ["body"] and "500 bytes" in item["msg"]
    assert small.get("/runs").json() == []  # and nothing was half-created


def test_run_with_10001_tasks_is_422_naming_the_field(client: TestClient) -> None:
    r = client.post("/runs", json={"tasks": many_tasks(10_001), "robots": ROBOTS})
    assert r.status_code == 422
    (item,) = assert_error_shape(r.json())
    assert item["loc"] == ["body", "tasks"] and "10000" in item["msg"]
    assert client.get("/runs").json() == []


def test_run_with_101_robots_is_422_naming_the_field(client: TestClient) -> None:
    r = client.post("/runs", json={"tasks": many_tasks(3), "robots": robots_rating_heavy(101)})
    assert r.status_code == 422
    (item,) = assert_error_shape(r.json())
    assert item["loc"] == ["body", "robots"] and "100" in item["msg"]
    assert client.get("/runs").json() == []


def test_the_limits_themselves_are_accepted(client: TestClient) -> None:
    r = client.post(
        "/allocate",
        json={"solver": "greedy", "tasks": many_tasks(10_000), "robots": robots_rating_heavy(100)},
    )
    assert r.status_code == 200, r.text[:500]
    assert len(r.json()["assignments"]) == 10_000
    assert len(r.json()["metrics"]["workload"]) == 100
