"""The console's sessions, forms and pages through the in-process client (the browser
tests in tests/console/test_*_browser.py drive the same pages in Chromium)."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from hashlib import sha256
from itertools import pairwise
from pathlib import Path

from fastapi.testclient import TestClient
from pydantic import SecretStr

from app.console import charts
from app.console.frontier import MAX_CAPS, compute_frontier, frontier
from app.domain.catalog import scenario
from app.http.auth import KeyRing, Role
from app.runs.spec import RunSpec
from tests.support.clients import ClientFactory
from tests.support.polling import eventually, wait_until

SUPERVISOR = "api-console-supervisor-key-1"
CLIENT = "api-console-client-key-00001"
KEYS = f"{SUPERVISOR}:supervisor,{CLIENT}:client"
TOKEN = re.compile(r'name="csrf_token" value="([^"]+)"')


def _sign_in(client: TestClient, key: str = SUPERVISOR, next_: str = "/console") -> int:
    form = client.get("/console/login")
    token = TOKEN.search(form.text)
    assert token, form.text
    answer = client.post(
        "/console/login",
        data={"api_key": key, "csrf_token": token[1], "next": next_},
        follow_redirects=False,
    )
    return answer.status_code


def _run(client: TestClient) -> str:
    created = client.post(
        "/runs", json={"scenario": "baseline", "reasoner": "rules"}, headers={"X-API-Key": CLIENT}
    )
    run_id = str(created.json()["id"])
    wait_until(client, run_id, ("completed",), headers={"X-API-Key": CLIENT})
    return run_id


def test_pages_need_a_session_and_redirect_to_sign_in(make_client: ClientFactory) -> None:
    client = make_client(api_keys=SecretStr(KEYS))
    answer = client.get("/console/reviews", follow_redirects=False)
    assert answer.status_code == 303
    assert answer.headers["location"] == "/console/login?next=/console/reviews"
    login = client.get("/console/login")
    assert login.status_code == 200 and login.headers["content-type"].startswith("text/html")
    assert 'name="api_key"' in login.text


def test_client_and_unknown_keys_are_refused_with_a_page(make_client: ClientFactory) -> None:
    client = make_client(api_keys=SecretStr(KEYS))
    assert _sign_in(client, CLIENT) == 403
    assert _sign_in(client, "x" * 20) == 401
    assert "ltaa_console" not in client.cookies
    assert _sign_in(client, SUPERVISOR) == 303
    assert client.get("/console").status_code == 200


def test_sign_in_without_its_token_is_refused(make_client: ClientFactory) -> None:
    client = make_client(api_keys=SecretStr(KEYS))
    client.get("/console/login")
    answer = client.post("/console/login", data={"api_key": SUPERVISOR}, follow_redirects=False)
    assert answer.status_code == 403
    forged = client.post(
        "/console/login",
        data={"api_key": SUPERVISOR, "csrf_token": "guess"},
        follow_redirects=False,
    )
    assert forged.status_code == 403


def test_next_never_leaves_the_console(make_client: ClientFactory) -> None:
    client = make_client(api_keys=SecretStr(KEYS))
    for target in ("//example.org/x", "https://example.org", "/runs"):
        client.cookies.clear()  # signed out: the sign-in form again
        token = TOKEN.search(client.get("/console/login").text)
        assert token
        answer = client.post(
            "/console/login",
            data={"api_key": SUPERVISOR, "csrf_token": token[1], "next": target},
            follow_redirects=False,
        )
        assert answer.headers["location"] == "/console"


def test_a_session_expires(make_client: ClientFactory) -> None:
    client = make_client(api_keys=SecretStr(KEYS), console_session_s=1.0)
    assert _sign_in(client) == 303
    assert client.get("/console", follow_redirects=False).status_code == 200
    eventually(
        lambda: client.get("/console", follow_redirects=False).status_code,
        until=lambda status: status == 303,
        timeout=10,
        what="the session expired: the page redirects to sign-in",
    )


def test_the_cookie_opens_no_json_endpoint_but_the_event_stream(
    make_client: ClientFactory,
) -> None:
    client = make_client(api_keys=SecretStr(KEYS))
    run_id = _run(client)
    assert _sign_in(client) == 303
    assert client.get("/runs").status_code == 401
    assert client.get(f"/runs/{run_id}/trace").status_code == 401
    assert client.post(f"/runs/{run_id}/cancel").status_code == 401
    stream = client.get(f"/runs/{run_id}/events")
    assert stream.status_code == 200 and "event: decision" in stream.text


def test_the_stream_starts_after_a_cursor_given_as_a_query(make_client: ClientFactory) -> None:
    client = make_client(api_keys=SecretStr(KEYS))
    run_id = _run(client)
    auth = {"X-API-Key": SUPERVISOR}
    whole = client.get(f"/runs/{run_id}/events", headers=auth).text
    tail = client.get(f"/runs/{run_id}/events?after=0-30", headers=auth).text
    assert whole.count("event: decision") == 36
    assert tail.count("event: decision") == 6
    bad = client.get(f"/runs/{run_id}/events?after=nonsense", headers=auth)
    assert bad.status_code == 422
    assert bad.json()["detail"][0]["loc"] == ["query", "after"]


def test_with_access_control_off_the_console_is_open_and_says_so(client: TestClient) -> None:
    page = client.get("/console")
    assert page.status_code == 200
    assert "Access control is off" in page.text
    assert "ltaa_console" in client.cookies  # a keyless session: its forms carry a token
    run_id = _run(client)
    refused = client.post(f"/console/runs/{run_id}/cancel", data={})
    assert refused.status_code == 403


def test_the_run_page_shows_the_run(make_client: ClientFactory) -> None:
    client = make_client(api_keys=SecretStr(KEYS))
    run_id = _run(client)
    assert _sign_in(client) == 303
    page = client.get(f"/console/runs/{run_id}?decision=30")
    assert page.status_code == 200
    html = page.text
    assert 'id="decision-30" open' in html and 'id="decision-29"' in html
    # Page 2 (tasks 25-35) with eight criterion rows per decision.
    assert html.count('<tr data-criterion="') == 11 * 8
    assert 'value="36"' in html
    assert "this run" in html  # its point on the frontier, drawn in the page (small run)
    assert 'id="frontier" aria-live' in html  # nothing left to fetch
    data_dir: Path = client.app.state.settings.data_dir  # type: ignore[attr-defined]
    cache = data_dir / "console-cache" / f"frontier-{run_id}.json"
    assert cache.is_file()
    cache.unlink()
    fragment = client.get(f"/console/runs/{run_id}/frontier?fragment=1")
    assert fragment.status_code == 200 and "<svg" in fragment.text and "this run" in fragment.text
    assert cache.is_file()
    assert client.get(f"/console/runs/{run_id}/export.jsonl").text.count('"type": "decision"') == 36
    assert client.get("/console/runs/no-such-run").status_code == 404
    assert client.get(f"/console/runs/{run_id}/attempts/0/99").status_code == 404


def test_the_security_headers_keep_pages_to_this_server(make_client: ClientFactory) -> None:
    client = make_client(api_keys=SecretStr(KEYS))
    page = client.get("/console/login")
    assert "default-src 'self'" in page.headers["content-security-policy"]
    assert page.headers["x-frame-options"] == "DENY"
    assert page.headers["cache-control"] == "no-store"
    assert "http://" not in page.text and "https://" not in page.text


def test_a_session_fingerprint_names_no_key_and_ends_with_it() -> None:
    ring = KeyRing({SUPERVISOR: Role.SUPERVISOR})
    found = ring.fingerprint_of(SUPERVISOR)
    assert found is not None
    role, fingerprint = found
    assert role is Role.SUPERVISOR
    assert SUPERVISOR not in fingerprint
    assert fingerprint != sha256(SUPERVISOR.encode()).hexdigest()
    identified = ring.identify_fingerprint(fingerprint)
    assert identified is not None and identified[0] is Role.SUPERVISOR
    assert KeyRing({CLIENT: Role.SUPERVISOR}).identify_fingerprint(fingerprint) is None


def test_the_frontier_is_exact_bounded_and_cached(tmp_path: Path) -> None:
    spec = RunSpec.for_instance(scenario("baseline").instance, mode="balanced")
    points = compute_frontier(spec)
    assert len(points) <= MAX_CAPS
    # Looser caps never lose success; the uncapped optimum is last.
    ordered = [p for p in points if p.max_deviation is not None]
    assert all(a.expected_success <= b.expected_success + 1e-12 for a, b in pairwise(ordered))
    assert points[-1].max_deviation is None
    assert frontier(spec=spec, run_id="r1", cache_dir=tmp_path) == points
    cached = tmp_path / "frontier-r1.json"
    assert cached.is_file()
    cached.write_text(cached.read_text().replace('"balance_score": 100.0', '"balance_score": 99.0'))
    assert frontier(spec=spec, run_id="r1", cache_dir=tmp_path)[0].balance_score == 99.0


def test_charts_are_well_formed_svg_with_a_title() -> None:
    for svg in (
        charts.workload_chart(["a", "b<c"], [3, 5], 4.0, 3, 5),
        charts.balance_chart([float(i % 100) for i in range(10_000)], 10_000),
        charts.frontier_chart(
            [charts.PlotPoint("cap 0", 100.0, 70.0), charts.PlotPoint("no cap", 10.0, 80.0)],
            charts.PlotPoint("this run", 60.0, 75.0),
        ),
    ):
        root = ET.fromstring(str(svg))
        assert root.get("role") == "img"
        assert root.find("{http://www.w3.org/2000/svg}title") is not None
    line = ET.fromstring(str(charts.balance_chart([50.0] * 10_000, 10_000))).find(
        "{http://www.w3.org/2000/svg}polyline"
    )
    assert line is not None
    assert len(line.get("points", "").split()) <= charts.MAX_LINE_POINTS + 1


def test_the_cookie_is_secure_over_https(make_client: ClientFactory) -> None:
    client = make_client(api_keys=SecretStr(KEYS))
    client.base_url = client.base_url.copy_with(scheme="https")
    form = client.get("/console/login")
    token = TOKEN.search(form.text)
    assert token
    answer = client.post(
        "/console/login",
        data={"api_key": SUPERVISOR, "csrf_token": token[1]},
        follow_redirects=False,
    )
    assert answer.status_code == 303
    cookie = answer.headers["set-cookie"]
    assert "ltaa_console=" in cookie
    assert "Secure" in cookie and "HttpOnly" in cookie and "SameSite=strict" in cookie


def test_a_nul_character_in_a_console_form_is_refused_with_a_page_and_nothing_written(
    client: TestClient,
) -> None:
    # The console calls the services directly, past the API's body models: the services
    # refuse the NUL themselves (PostgreSQL could not store it).
    run_id = _run(client)
    token = TOKEN.search(client.get(f"/console/runs/{run_id}").text)
    assert token
    signed = client.post(
        f"/console/runs/{run_id}/signoff",
        data={"csrf_token": token[1], "statement": "checked\x00"},
        follow_redirects=False,
    )
    assert signed.status_code == 422, signed.text
    assert "NUL" in signed.text
    assert client.get(f"/runs/{run_id}").json()["signoffs"] == []

    review = {"scenario": "baseline", "reasoner": "rules", "review": {"on": ["every_decision"]}}
    waiting = str(client.post("/runs", json=review).json()["id"])
    wait_until(client, waiting, ("awaiting_review",))
    token = TOKEN.search(client.get("/console/reviews").text)
    assert token
    resolved = client.post(
        f"/console/runs/{waiting}/reviews/0",
        data={"csrf_token": token[1], "action": "override", "robot": "light", "reason": "x\x00"},
        follow_redirects=False,
    )
    assert resolved.status_code == 422, resolved.text
    assert "NUL" in resolved.text
    assert [r["run_id"] for r in client.get("/reviews").json()] == [waiting]
