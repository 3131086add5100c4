"""Access control: API keys with the client and supervisor roles, in the one error shape."""

from __future__ import annotations

import logging
from typing import Any

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from pydantic import SecretStr

from app.config import Settings, get_settings
from app.http.auth import ApiKeysError, InsecureBindError, Role, parse_api_keys
from app.main import create_app
from tests.support.clients import ClientFactory
from tests.support.polling import wait_until

CLIENT_KEY = "client-key-7Hq2vN9xLp4Rt8Zw"
SUPERVISOR_KEY = "supervisor-key-Jm3Kd8Qw2Vx6Bn5Y"
KEYS = SecretStr(f"{CLIENT_KEY}:client, {SUPERVISOR_KEY}:supervisor")
AS_CLIENT = {"Authorization": f"Bearer {CLIENT_KEY}"}
AS_SUPERVISOR = {"Authorization": f"Bearer {SUPERVISOR_KEY}"}
BASELINE = {"scenario": "baseline", "mode": "balanced"}

# (method, path) of every endpoint behind a key; {id} is replaced by a real run id.
CLIENT_ENDPOINTS = [
    ("GET", "/solvers"),
    ("GET", "/fleet/robots"),
    ("GET", "/scenarios"),
    ("POST", "/allocate"),
    ("POST", "/runs"),
    ("GET", "/runs"),
    ("GET", "/runs/{id}"),
    ("GET", "/audit/public-key"),
    ("POST", "/runs/{id}/execution"),
    ("POST", "/runs/{id}/revisions"),
    ("GET", "/runs/{id}/revisions"),
    ("GET", "/runs/{id}/diff"),
    ("GET", "/runs/{id}/schedule"),
    ("POST", "/schedules/import"),
    ("GET", "/sites"),
    ("GET", "/sites/{site}/estimates"),
]
SUPERVISOR_ENDPOINTS = [
    ("GET", "/runs/{id}/trace"),
    ("GET", "/runs/{id}/trace/verify"),
    ("GET", "/runs/{id}/events"),
    ("POST", "/runs/{id}/resume"),
    ("POST", "/runs/{id}/cancel"),
    ("POST", "/runs/{id}/signoff"),
    ("GET", "/reviews"),
    ("POST", "/runs/{id}/reviews/{task_index}"),
    ("GET", "/metrics"),
    ("POST", "/webhooks"),
    ("GET", "/webhooks"),
    ("GET", "/webhooks/{webhook_id}"),
    ("DELETE", "/webhooks/{webhook_id}"),
    ("POST", "/webhooks/{webhook_id}/rotate-secret"),
    ("GET", "/webhooks/{webhook_id}/deliveries"),
    ("POST", "/webhooks/{webhook_id}/deliveries/{delivery_id}/retry"),
    ("POST", "/admin/backup"),
    ("POST", "/admin/archive"),
]


@pytest.fixture
def secured(make_client: ClientFactory) -> TestClient:
    return make_client(api_keys=KEYS)


def _wait_completed(client: TestClient, run_id: str) -> None:
    wait_until(client, run_id, ("completed",), timeout=60, headers=AS_CLIENT)


def _call(
    client: TestClient, method: str, path: str, headers: dict[str, str], run_id: str = "0" * 32
) -> Any:
    body = {"solver": "greedy", **BASELINE} if path == "/allocate" else BASELINE
    return client.request(
        method,
        path.replace("{id}", run_id),
        headers=headers,
        json=body if method == "POST" else None,
    )


def _only_error(response: Any, status: int, type_: str) -> dict[str, Any]:
    assert response.status_code == status, response.text
    detail = response.json()["detail"]
    assert len(detail) == 1 and set(detail[0]) == {"loc", "msg", "type"}
    assert detail[0]["type"] == type_ and detail[0]["loc"][0] == "header"
    return dict(detail[0])


@pytest.mark.parametrize(("method", "path"), CLIENT_ENDPOINTS + SUPERVISOR_ENDPOINTS)
def test_no_key_is_401_with_a_bearer_challenge(secured: TestClient, method: str, path: str) -> None:
    response = _call(secured, method, path, {})
    err = _only_error(response, 401, "missing_api_key")
    assert response.headers["www-authenticate"] == "Bearer"
    assert "Authorization: Bearer" in err["msg"] and "X-API-Key" in err["msg"]


@pytest.mark.parametrize(
    "headers",
    [
        {"Authorization": f"Bearer {SUPERVISOR_KEY}x"},
        {"X-API-Key": CLIENT_KEY[:-1]},
        {"Authorization": f"bearer {SUPERVISOR_KEY.upper()}"},
    ],
)
def test_an_unknown_key_is_401(secured: TestClient, headers: dict[str, str]) -> None:
    response = secured.get("/runs", headers=headers)
    err = _only_error(response, 401, "invalid_api_key")
    assert err["msg"] == "the API key is not valid"
    assert response.headers["www-authenticate"].startswith("Bearer error=")


def test_two_different_keys_are_401_whichever_is_valid(secured: TestClient) -> None:
    both = {**AS_SUPERVISOR, "X-API-Key": CLIENT_KEY}
    err = _only_error(secured.get("/runs", headers=both), 401, "conflicting_api_keys")
    assert err["loc"] == ["header", "x-api-key"] and "send one key" in err["msg"]
    same = {**AS_CLIENT, "X-API-Key": CLIENT_KEY}
    assert secured.get("/runs", headers=same).status_code == 200


def test_a_key_in_another_scheme_is_401_and_says_use_bearer(secured: TestClient) -> None:
    response = secured.get("/runs", headers={"Authorization": f"Basic {CLIENT_KEY}"})
    assert "Bearer scheme" in _only_error(response, 401, "missing_api_key")["msg"]


def test_client_runs_and_allocates_but_supervisor_endpoints_are_403(
    secured: TestClient,
) -> None:
    allocated = secured.post("/allocate", json={"solver": "dp", **BASELINE}, headers=AS_CLIENT)
    assert allocated.status_code == 200 and len(allocated.json()["assignments"]) == 36
    for path in ("/solvers", "/scenarios", "/runs"):
        assert secured.get(path, headers=AS_CLIENT).status_code == 200, path
    created = secured.post("/runs", json=BASELINE, headers=AS_CLIENT)
    assert created.status_code == 202
    run_id = created.json()["id"]
    _wait_completed(secured, run_id)

    for method, path in SUPERVISOR_ENDPOINTS:
        err = _only_error(_call(secured, method, path, AS_CLIENT, run_id), 403, "insufficient_role")
        assert err["msg"] == (
            "this endpoint needs the supervisor role; the API key sent has the client role"
        ), path

    trace = secured.get(f"/runs/{run_id}/trace", headers=AS_SUPERVISOR)
    assert trace.status_code == 200 and len(trace.json()["decisions"]) == 36
    by_header = secured.get(f"/runs/{run_id}/trace", headers={"X-API-Key": SUPERVISOR_KEY})
    assert by_header.status_code == 200
    assert secured.get("/metrics", headers=AS_SUPERVISOR).status_code == 200
    # Supervisors may do everything clients may.
    assert secured.get(f"/runs/{run_id}", headers=AS_SUPERVISOR).status_code == 200
    # Roles are settled before existence: a client cannot probe run ids through a 404.
    assert secured.get(f"/runs/{'0' * 32}/trace", headers=AS_CLIENT).status_code == 403
    assert secured.get(f"/runs/{'0' * 32}/trace", headers=AS_SUPERVISOR).status_code == 404


def test_health_and_docs_stay_open(secured: TestClient) -> None:
    for path in ("/health", "/docs", "/openapi.json"):
        assert secured.get(path).status_code == 200, path
    schemes = secured.get("/openapi.json").json()["components"]["securitySchemes"]
    assert schemes["bearer"]["scheme"] == "bearer" and schemes["apiKey"]["name"] == "X-API-Key"


def test_every_other_route_requires_a_key(secured: TestClient) -> None:
    """A route added later without ClientDep or SupervisorDep fails here: the security
    schemes appear in an operation's OpenAPI only when it depends on authentication."""
    paths = secured.get("/openapi.json").json()["paths"]
    operations = {
        (method.upper(), path): op for path, ops in paths.items() for method, op in ops.items()
    }
    guarded = {
        (m, p.replace("{run_id}", "{id}"))
        for (m, p), op in operations.items()
        if op.get("security") == [{"bearer": []}, {"apiKey": []}]
    }
    assert guarded == set(CLIENT_ENDPOINTS + SUPERVISOR_ENDPOINTS)
    assert set(operations) - {(m, p.replace("{id}", "{run_id}")) for m, p in guarded} == {
        ("GET", "/health"),
        ("HEAD", "/health"),
    }


def test_without_keys_access_is_open_and_startup_says_so(
    make_client: ClientFactory,
    caplog: pytest.LogCaptureFixture,
) -> None:
    with caplog.at_level(logging.INFO, logger="ltaa"):
        client = make_client()
    assert any(
        "access control is off" in r.getMessage() and r.levelno == logging.WARNING
        for r in caplog.records
    )
    assert client.get(f"/runs/{'0' * 32}/trace").status_code == 404  # open: reaches the route
    assert client.get("/metrics").status_code == 200


@pytest.mark.parametrize("host", ["0.0.0.0", "::", "192.168.1.20", "api.example.org"])
def test_refuses_to_start_beyond_loopback_without_keys(settings: Settings, host: str) -> None:
    with pytest.raises(InsecureBindError, match="refusing to start") as raised:
        create_app(settings.model_copy(update={"host": host}))
    assert "LTAA_API_KEYS" in str(raised.value) and host in str(raised.value)


@pytest.mark.parametrize("host", ["127.0.0.1", "localhost", "::1", "127.0.0.2"])
def test_loopback_without_keys_and_anywhere_with_keys_start(settings: Settings, host: str) -> None:
    create_app(settings.model_copy(update={"host": host}))
    create_app(settings.model_copy(update={"host": "0.0.0.0", "api_keys": KEYS}))


def test_keys_never_appear_in_logs(
    make_client: ClientFactory, caplog: pytest.LogCaptureFixture, capsys: pytest.CaptureFixture[str]
) -> None:
    near_miss = SUPERVISOR_KEY[:-1] + "?"
    with caplog.at_level(logging.DEBUG):
        client = make_client(api_keys=KEYS)
        client.get("/runs", headers={"Authorization": f"Bearer {near_miss}"})
        client.get("/runs", headers={"X-API-Key": near_miss})
        run_id = client.post("/runs", json=BASELINE, headers=AS_CLIENT).json()["id"]
        _wait_completed(client, run_id)
        client.get(f"/runs/{run_id}/trace", headers=AS_CLIENT)
        client.get(f"/runs/{run_id}/trace", headers=AS_SUPERVISOR)
        client.get("/metrics", headers={"X-API-Key": SUPERVISOR_KEY})
    assert any("rejected an unknown API key" in r.getMessage() for r in caplog.records)
    logged = "\n".join(f"{r.getMessage()} {r.__dict__!r}" for r in caplog.records)
    logged += capsys.readouterr().err
    for secret in (CLIENT_KEY, SUPERVISOR_KEY, near_miss):
        assert secret not in logged
    app = client.app
    assert isinstance(app, FastAPI)
    settings = app.state.settings
    assert SUPERVISOR_KEY not in repr(settings) and SUPERVISOR_KEY not in str(
        settings.model_dump(mode="json")
    )


def test_keys_from_the_environment_stay_hidden(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LTAA_API_KEYS", KEYS.get_secret_value())
    settings = get_settings()
    assert settings.api_keys == KEYS
    assert CLIENT_KEY not in repr(settings) and CLIENT_KEY not in settings.model_dump_json()


def test_key_format() -> None:
    assert parse_api_keys(f" {CLIENT_KEY}:client ,, a:b:c:{SUPERVISOR_KEY}:Supervisor ") == {
        CLIENT_KEY: Role.CLIENT,
        f"a:b:c:{SUPERVISOR_KEY}": Role.SUPERVISOR,
    }
    assert parse_api_keys("") == {}


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        (CLIENT_KEY, "entry 1 is not KEY:ROLE"),
        (f"{CLIENT_KEY}:client,{SUPERVISOR_KEY}:admin", "entry 2 has an unknown role"),
        ("short-key:client", "at least 16 characters"),
        (f"{CLIENT_KEY}:client,{CLIENT_KEY}:supervisor", "entry 2 repeats an earlier key"),
    ],
)
def test_bad_key_settings_fail_start_up_without_quoting_keys(
    settings: Settings,
    raw: str,
    message: str,
) -> None:
    with pytest.raises(ApiKeysError, match=message) as raised:
        create_app(settings.model_copy(update={"api_keys": SecretStr(raw)}))
    assert CLIENT_KEY not in str(raised.value) and "short-key" not in str(raised.value)
