"""GET /health, /solvers, /scenarios, and the OpenAPI document."""

from __future__ import annotations

from fastapi.testclient import TestClient

from app.config import Settings
from app.main import app_version, create_app


def test_health_reports_ok_version_and_solvers(client: TestClient) -> None:
    r = client.get("/health")
    assert r.status_code == 200
    body = r.json()
    assert body["status"] == "ok"
    assert body["version"] == app_version() != "unknown"
    assert {"greedy", "brute_force", "dp", "optimal"} <= set(body["solvers"])
    assert body["default_reasoner"] == "rules"
    head = client.head("/health")  # how load balancers and health checks often probe
    assert head.status_code == 200 and head.content == b""


def test_solvers_describe_exactness_and_limits(client: TestClient) -> None:
    r = client.get("/solvers")
    assert r.status_code == 200
    solvers = {s["name"]: s for s in r.json()}
    assert {"greedy", "brute_force", "dp", "optimal"} <= set(solvers)
    for s in solvers.values():
        assert set(s) == {"name", "description", "exact", "kind", "limits"}
        assert s["kind"] == ("exact" if s["exact"] else "approximate")
        assert s["description"] and s["limits"]
    assert solvers["greedy"]["exact"] is False
    assert all(solvers[n]["exact"] for n in ("brute_force", "dp", "optimal"))
    assert "3^12" in solvers["brute_force"]["limits"]


def test_scenarios_include_tasks_and_robots(client: TestClient) -> None:
    r = client.get("/scenarios")
    assert r.status_code == 200
    scenarios = {s["name"]: s for s in r.json()}
    untimed = {"baseline", "heavy_excels", "medium_excels", "light_excels"}
    assert set(scenarios) == untimed | {"baseline_timed", "baseline_team"}
    assert {name for name, s in scenarios.items() if not s["timed"]} == untimed
    assert {name for name, s in scenarios.items() if s["team"]} == {"baseline_team"}
    baseline = scenarios["baseline"]
    assert "travel" not in baseline and "start" not in baseline
    assert baseline["description"]
    assert len(baseline["tasks"]) == 36
    assert baseline["tasks"][14] == {
        "id": 300,
        "name": "Navigation",
        "type": "MapGoal",
        "features": ["heavy"],
    }
    robots = {r["name"]: r for r in baseline["robots"]}
    assert list(robots) == ["light", "medium", "heavy"]
    assert robots["light"]["label"] == "Light Robot"
    assert robots["light"]["description"]
    assert robots["light"]["success"] == {"careful": 0.9, "dexterous": 0.8, "heavy": 0.5}
    assert robots["heavy"]["success"]["heavy"] == 0.9
    assert scenarios["heavy_excels"]["robots"][2]["success"]["heavy"] == 0.95


def test_a_timed_scenario_lists_its_times_and_they_describe_the_same_instance(
    client: TestClient,
) -> None:
    """An integrator can read baseline_timed from GET /scenarios, edit it and send it back
    as its own tasks: sent unchanged, it is the same instance as the scenario's name."""
    timed = next(s for s in client.get("/scenarios").json() if s["name"] == "baseline_timed")
    assert timed["timed"] is True and len(timed["tasks"]) == 36
    assert all(set(t["duration"]) == {"light", "medium", "heavy"} for t in timed["tasks"])
    assert all(t["zone"] for t in timed["tasks"]) and any(t.get("after") for t in timed["tasks"])
    assert all(r["zone"] and len(r["available"]) == 2 for r in timed["robots"])
    assert timed["travel"] and timed["start"]
    by_name = client.post("/allocate", json={"scenario": "baseline_timed", "solver": "greedy"})
    own = {k: timed[k] for k in ("tasks", "robots", "travel", "start")}
    by_content = client.post("/allocate", json={**own, "solver": "greedy"})
    assert by_name.status_code == by_content.status_code == 200, by_content.text
    for key in ("assignments", "metrics", "schedule"):
        assert by_content.json()[key] == by_name.json()[key]


def test_openapi_documents_every_route_and_allocate_examples(client: TestClient) -> None:
    doc = client.get("/openapi.json").json()
    for path in ("/health", "/solvers", "/scenarios", "/allocate"):
        for op in doc["paths"][path].values():
            assert op.get("description"), path
            assert "200" in op["responses"]
    body = doc["paths"]["/allocate"]["post"]["requestBody"]["content"]["application/json"]
    assert {"baseline", "custom"} <= set(body["examples"])
    assert client.get("/docs").status_code == 200


def test_create_app_keeps_the_given_settings_and_creates_the_data_dir(
    settings: Settings,
) -> None:
    app = create_app(settings)
    assert app.state.settings is settings
    assert not settings.data_dir.exists()
    with TestClient(app) as c:
        assert c.get("/health").status_code == 200
        assert settings.data_dir.is_dir()
