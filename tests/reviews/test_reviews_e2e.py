"""Supervisor reviews against the real server (uvicorn subprocess, SIGKILL), the real
Anthropic SDK against the fake Messages API, and two processes on PostgreSQL."""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from app.graph.pause import PausePoint
from app.http.auth import key_fingerprint
from app.reasoners.rules import compose_answer
from tests.fakes.fake_messages_api import FakeMessagesAPI, Reply, context_from_prompt, prompt_of
from tests.fakes.scripted_reasoner import GARBAGE
from tests.support.polling import eventually
from tests.support.postgres import fresh_database, query
from tests.support.server import Server

pytestmark = pytest.mark.e2e

SUPERVISOR_KEY = "supervisor-key-Jm3Kd8Qw2Vx6Bn5Y"
CLIENT_KEY = "client-key-7Hq2vN9xLp4Rt8Zw"
KEYS = {
    "LTAA_API_KEYS": f"{SUPERVISOR_KEY}:supervisor,{CLIENT_KEY}:client",
    "LTAA_API_KEY_NAMES": f"{key_fingerprint(SUPERVISOR_KEY)}=Dana Safety",
}
AS_SUPERVISOR = {"Authorization": f"Bearer {SUPERVISOR_KEY}"}
AS_CLIENT = {"Authorization": f"Bearer {CLIENT_KEY}"}
INVALID_TASK = 5


def _client(server: Server) -> httpx.Client:
    return httpx.Client(base_url=server.url, timeout=30, headers=AS_SUPERVISOR)


def _wait(server: Server, run_id: str, statuses: tuple[str, ...]) -> dict[str, Any]:
    with _client(server) as c:
        state: dict[str, Any] = eventually(
            lambda: c.get(f"/runs/{run_id}").json(),
            until=lambda s: s["status"] in statuses,
            timeout=120,
            what=f"run {run_id} reached {' or '.join(statuses)}",
        )
    return state


def _events(server: Server, run_id: str) -> list[dict[str, Any]]:
    with _client(server) as c:
        events: list[dict[str, Any]] = c.get(f"/runs/{run_id}/trace").json()["events"]
    return events


def invalid_at_task_5(request: dict[str, Any]) -> Reply:
    ctx = context_from_prompt(prompt_of(request))
    return Reply.answer(GARBAGE if ctx.task_index == INVALID_TASK else compose_answer(ctx))


def test_fallback_review_survives_sigkill_and_an_override_completes_the_run(
    tmp_path: Path,
) -> None:
    body = {
        "scenario": "baseline",
        "reasoner": "anthropic",
        "model": "claude-test",
        "review": {"on": ["fallback"]},
    }
    data = tmp_path / "data"
    with FakeMessagesAPI(default=invalid_at_task_5) as api:
        env = {
            **KEYS,
            "LTAA_ANTHROPIC_API_KEY": "test-key",
            "LTAA_ANTHROPIC_BASE_URL": api.base_url,
        }
        server = Server(data, env=env).start()
        try:
            with _client(server) as c:
                run_id = c.post("/runs", json=body, headers=AS_CLIENT).json()["id"]
            _wait(server, run_id, ("awaiting_review",))
            with _client(server) as c:
                reviews = c.get("/reviews").json()
                assert c.get("/reviews", headers=AS_CLIENT).status_code == 403
            assert len(reviews) == 1
            review = reviews[0]
            assert (review["run_id"], review["task_index"]) == (run_id, INVALID_TASK)
            assert review["triggers"] == ["fallback"] and review["proposal"]["fallback"] is True
            assert [a["robot"] for a in review["alternatives"]] == ["light", "medium", "heavy"]
            calls_before = len(api.requests)
            # Tasks 0-4 once each; task 5 four times (first try and three retries).
            assert calls_before == INVALID_TASK + 4
        finally:
            server.kill()

        server = Server(data, env=env).start()
        try:
            assert _wait(server, run_id, ("awaiting_review",))["status"] == "awaiting_review"
            kinds = [e["kind"] for e in _events(server, run_id)]
            assert kinds == ["created", "started", "review_requested"]
            assert len(api.requests) == calls_before  # nothing re-ran after the restart
            with _client(server) as c:
                answer = c.post(
                    f"/runs/{run_id}/reviews/{INVALID_TASK}",
                    json={
                        "action": "override",
                        "robot": "medium",
                        "reason": "light is on the scaffold",
                    },
                )
                assert answer.status_code == 200, answer.text
                done = _wait(server, run_id, ("completed", "failed"))
                trace = c.get(f"/runs/{run_id}/trace").json()
                verify = c.get(f"/runs/{run_id}/trace/verify").json()
        finally:
            server.stop()

    assert done["status"] == "completed", done
    decision = trace["decisions"][INVALID_TASK]
    assert decision["robot"] == "medium" and decision["fallback"] is True
    assert decision["review"]["overridden_from"] == review["proposal"]["robot"] != "medium"
    assert decision["review"]["reviewer"] == "Dana Safety"
    assert decision["review"]["reason"] == "light is on the scaffold"
    medium = 1
    assert decision["loads_after"][medium] == decision["loads_before"][medium] + 1
    assert trace["decisions"][INVALID_TASK + 1]["loads_before"] == decision["loads_after"]
    assert done["assignments"][INVALID_TASK]["robot"] == "medium"
    assert sum(done["workload"].values()) == 36
    assert verify["ok"] is True
    # Every attempt asked the API exactly once.
    per_task = Counter(context_from_prompt(prompt_of(r)).task_index for r in api.requests)
    assert per_task[INVALID_TASK] == 4 and all(
        n == 1 for t, n in per_task.items() if t != INVALID_TASK
    )
    assert len(per_task) == 36 and done["resumes"] == 0


def test_an_approval_killed_at_the_resumes_first_node_is_applied_once(tmp_path: Path) -> None:
    body = {"scenario": "baseline", "review": {"task_ids": [str(INVALID_TASK)]}}
    data = tmp_path / "data"
    # Held after finalize of task 5 on its second pass (the first pass pauses for review
    # inside finalize, before the hold): the resolution is applied, nothing stored yet.
    server = Server(data, env=KEYS).start(pause=PausePoint(INVALID_TASK, "finalize", after=True))
    try:
        with _client(server) as c:
            run_id = c.post("/runs", json=body).json()["id"]
        _wait(server, run_id, ("awaiting_review",))
        with _client(server) as c:
            answer = c.post(f"/runs/{run_id}/reviews/{INVALID_TASK}", json={"action": "approve"})
        assert answer.status_code == 200, answer.text
        server.wait_for_log(PausePoint(INVALID_TASK, "finalize", after=True).message())
    finally:
        server.kill()

    server = Server(data, env=KEYS).start()
    try:
        done = _wait(server, run_id, ("completed", "failed", "awaiting_review"))
        with _client(server) as c:
            trace = c.get(f"/runs/{run_id}/trace").json()
            verify = c.get(f"/runs/{run_id}/trace/verify").json()
    finally:
        server.stop()
    assert done["status"] == "completed", done
    kinds = [e["kind"] for e in trace["events"]]
    assert kinds.count("review_requested") == kinds.count("review_resolved") == 1
    assert kinds.count("resumed") == 1 and done["resumes"] == 1  # the kill, not the review
    reviewed = [d for d in trace["decisions"] if d["review"] is not None]
    assert [d["task_index"] for d in reviewed] == [INVALID_TASK]
    assert reviewed[0]["review"]["action"] == "approve"
    assert [d["task_index"] for d in trace["decisions"]] == list(range(36))
    assert verify["ok"] is True


@pytest.fixture
def postgres_url() -> Iterator[str]:
    with fresh_database("ltaa_reviews") as url:
        yield url


def test_postgres_two_processes_apply_each_resolution_once_and_never_claim_a_waiting_run(
    tmp_path: Path, postgres_url: str
) -> None:
    env = {**KEYS, "LTAA_DATABASE_URL": postgres_url, "LTAA_CLAIM_POLL_S": "0.2"}
    a = Server(tmp_path / "a", env={**env, "LTAA_WORKER_NAME": "api-a"}).start()
    b = Server(tmp_path / "b", env={**env, "LTAA_WORKER_NAME": "api-b"}).start()
    tasks = [{"id": f"T{i}", "features": ["heavy" if i % 2 else "careful"]} for i in range(6)]
    robots = [
        {"name": "x", "success": {"heavy": 0.9, "careful": 0.4}},
        {"name": "y", "success": {"heavy": 0.5, "careful": 0.8}},
    ]
    body = {"tasks": tasks, "robots": robots, "review": {"on": ["every_decision"]}}
    try:
        with _client(a) as c:
            run_id = c.post("/runs", json=body).json()["id"]
        for task_index in range(6):
            _wait(a, run_id, ("awaiting_review",))
            # A waiting run is nobody's: no lease, and no poller takes it. A property that
            # must hold for a while, so it is sampled over three claim polls of each process.
            deadline = time.monotonic() + 0.6
            while time.monotonic() < deadline:
                status, owner = query(
                    postgres_url, "SELECT status, lease_owner FROM runs WHERE id = %s", run_id
                )[0]
                assert (status, owner) == ("awaiting_review", None)
                time.sleep(0.1)
            if task_index == 2:
                # Both processes at once: the database lets exactly one through.
                barrier = threading.Barrier(2)
                codes: list[int] = []

                def race(
                    server: Server, barrier: threading.Barrier = barrier, codes: list[int] = codes
                ) -> None:
                    with _client(server) as c:
                        barrier.wait()
                        url = f"/runs/{run_id}/reviews/2"
                        codes.append(c.post(url, json={"action": "approve"}).status_code)

                threads = [threading.Thread(target=race, args=(s,)) for s in (a, b)]
                for t in threads:
                    t.start()
                for t in threads:
                    t.join()
                assert sorted(codes) == [200, 409]
                continue
            resolver = a if task_index % 2 else b  # each process resolves every other one
            with _client(resolver) as c:
                answer = c.post(
                    f"/runs/{run_id}/reviews/{task_index}",
                    json={"action": "override", "robot": "x", "reason": "x is on site"}
                    if task_index == 0
                    else {"action": "approve"},
                )
            assert answer.status_code == 200, answer.text
            with _client(a if resolver is b else b) as c:  # the other process: too late
                late = c.post(f"/runs/{run_id}/reviews/{task_index}", json={"action": "approve"})
            assert late.status_code == 409
        done = _wait(b, run_id, ("completed", "failed"))
        events = _events(b, run_id)
    finally:
        a.stop()
        b.stop()
    assert done["status"] == "completed", done
    kinds = [e["kind"] for e in events]
    assert kinds.count("review_requested") == kinds.count("review_resolved") == 6
    assert kinds.count("started") == 1 and "resumed" not in kinds
    rows = query(
        postgres_url,
        "SELECT task_index, robot_name, review IS NOT NULL FROM decisions "
        "WHERE run_id = %s ORDER BY task_index",
        run_id,
    )
    assert [r[0] for r in rows] == list(range(6)) and all(r[2] for r in rows)
    assert rows[0][1] == "x"


def test_the_cli_lists_and_resolves_reviews_against_a_real_server(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from app.cli import cli

    runner = CliRunner()
    server = Server(tmp_path / "data", env=KEYS).start()
    try:
        with _client(server) as c:
            run_id = c.post("/runs", json={"scenario": "baseline", "review": {"task_ids": ["3"]}})
            run_id = run_id.json()["id"]
        _wait(server, run_id, ("awaiting_review",))
        base = ["--url", server.url, "--key", SUPERVISOR_KEY]
        listed = runner.invoke(cli, ["reviews", *base], env={"COLUMNS": "240"})
        assert listed.exit_code == 0, listed.output
        assert run_id in listed.output and "3 (3: Backward)" in listed.output
        refused = runner.invoke(cli, ["reviews", "--url", server.url, "--key", CLIENT_KEY])
        assert refused.exit_code == 1 and "403" in refused.output

        no_reason = runner.invoke(cli, ["review", run_id, "3", "--override", "light", *base])
        assert no_reason.exit_code == 2 and "--reason" in no_reason.output
        both = runner.invoke(cli, ["review", run_id, "3", "--approve", "--override", "x", *base])
        assert both.exit_code == 2
        unknown = runner.invoke(
            cli, ["review", run_id, "3", "--override", "crane", "--reason", "r", *base]
        )
        assert unknown.exit_code == 1 and "crane" in unknown.output

        done = runner.invoke(
            cli,
            [
                "review",
                run_id,
                "3",
                "--override",
                "light",
                "--reason",
                "heavy is refuelling",
                *base,
            ],
        )
        assert done.exit_code == 0, done.output
        assert "overridden to light by Dana Safety" in done.output
        state = _wait(server, run_id, ("completed", "failed"))
        again = runner.invoke(cli, ["review", run_id, "3", "--approve", *base])
        assert again.exit_code == 1 and "409" in again.output
        team = _cli_team_override(runner, server, base)
    finally:
        server.stop()
    assert state["status"] == "completed"
    assert state["assignments"][3]["robot"] == "light"
    assert state["assignments"][3]["review"]["reviewer"] == "Dana Safety"
    assert [m["robot"] for m in team["team"]] == ["arm", "lifter"]
    assert team["review"]["overridden_from_team"] != team["team"]


def _cli_team_override(runner: Any, server: Server, base: list[str]) -> dict[str, Any]:
    """docs/reviews.md#reviews-of-team-decisions: `ltaa reviews` names the proposed team's
    members, `ltaa review --team` overrides it; one robot on a team decision is refused."""
    from app.cli import cli
    from tests.allocation.test_api_teams import TEAM_BODY

    with _client(server) as c:
        created = c.post("/runs", json={**TEAM_BODY, "review": {"task_ids": ["beam"]}})
        run_id = created.json()["id"]
    _wait(server, run_id, ("awaiting_review",))
    listed = runner.invoke(cli, ["reviews", *base], env={"COLUMNS": "240"})
    assert listed.exit_code == 0 and "crane + lifter" in listed.output, listed.output
    one = runner.invoke(cli, ["review", run_id, "0", "--override", "arm", "--reason", "r", *base])
    assert one.exit_code == 1 and "send `team`" in one.output, one.output
    done = runner.invoke(
        cli,
        ["review", run_id, "0", "--team", "arm:heavy,lifter:heavy", "--reason", "r", *base],
    )
    assert done.exit_code == 0 and "overridden to arm + lifter" in done.output, done.output
    state = _wait(server, run_id, ("completed", "failed"))
    assert state["status"] == "completed", state
    return dict(state["assignments"][0])
