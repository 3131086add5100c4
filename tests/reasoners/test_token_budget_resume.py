"""The token budget across a SIGKILL: a restarted run reads what it spent from its stored
attempts, switches to the rules reasoner at the same task as an uninterrupted run, and
records the switch once."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from app.graph.pause import PausePoint
from tests.fakes.fake_messages_api import FakeMessagesAPI
from tests.support.server import Server

pytestmark = pytest.mark.e2e

N_TASKS = 6
PAUSE_AT = 3  # the killed server holds every run inside task 3's reasoning node
HELD = PausePoint(PAUSE_AT, "reason", after=False)


def _run(server: Server, body: dict[str, Any]) -> str:
    with server.client() as c:
        response = c.post("/runs", json=body)
    assert response.status_code == 202, response.text
    return str(response.json()["id"])


def _finished(server: Server, run_id: str) -> tuple[dict[str, Any], dict[str, Any]]:
    state = server.wait_for(run_id, lambda s: s["status"] in ("completed", "failed"))
    assert state["status"] == "completed", state
    with server.client() as c:
        return state, c.get(f"/runs/{run_id}/trace").json()


def _record(state: dict[str, Any], trace: dict[str, Any]) -> dict[str, Any]:
    """What must not depend on a crash: the switch, who answered, what was spent."""
    return {
        "budget_events": [e["detail"] for e in trace["events"] if e["kind"] == "budget_exhausted"],
        "attempts": [
            [
                (a["model"], a["input_tokens"], a["output_tokens"], a["accepted"])
                for a in d["attempts"]
            ]
            for d in trace["decisions"]
        ],
        "assignments": [(a["task_id"], a["robot"]) for a in state["assignments"]],
        "usage": state["usage"],
    }


def test_a_budgeted_run_killed_before_and_after_its_switch_switches_at_the_same_task(
    tmp_path: Path,
) -> None:
    data = tmp_path / "data"
    with FakeMessagesAPI() as api:
        env = {"LTAA_ANTHROPIC_API_KEY": "test-key", "LTAA_ANTHROPIC_BASE_URL": api.base_url}
        server = Server(data, env=env).start()
        try:
            with server.client() as c:
                scenario = next(s for s in c.get("/scenarios").json() if s["name"] == "baseline")
            body = {
                "tasks": scenario["tasks"][:N_TASKS],
                "robots": scenario["robots"],
                "reasoner": "anthropic",
                "model": "claude-test",
            }
            # What each task costs, from an unlimited run answered first time everywhere.
            _, unlimited = _finished(server, _run(server, body))
            cost = [
                sum(a["input_tokens"] + a["output_tokens"] for a in d["attempts"])
                for d in unlimited["decisions"]
            ]
            spent_before = [sum(cost[:k]) for k in range(N_TASKS + 1)]
            # Budgets reached exactly before task 3 (the kill lands before the switch)
            # and before task 2 (the kill lands after it: the event is already written).
            budgets = {"at kill": spent_before[PAUSE_AT], "before kill": spent_before[2]}
            references = {
                name: _record(*_finished(server, _run(server, {**body, "token_budget": budget})))
                for name, budget in budgets.items()
            }
        finally:
            server.stop()

        killed = Server(data, env=env).start(pause=HELD)
        try:
            ids = {
                name: _run(killed, {**body, "token_budget": budget})
                for name, budget in budgets.items()
            }
            for run_id in ids.values():
                killed.wait_for(run_id, lambda s: s["progress"]["allocated"] >= PAUSE_AT)
            killed.wait_for_log(HELD.message(), count=len(ids))  # both runs held there
            with killed.client() as c:
                events = {
                    name: [e["kind"] for e in c.get(f"/runs/{i}/trace").json()["events"]]
                    for name, i in ids.items()
                }
        finally:
            killed.kill()
        assert "budget_exhausted" not in events["at kill"]
        assert events["before kill"].count("budget_exhausted") == 1

        restarted = Server(data, env=env).start()
        try:
            resumed = {name: _finished(restarted, run_id) for name, run_id in ids.items()}
        finally:
            restarted.stop()

    assert references["at kill"]["budget_events"] == [
        {"task_index": 3, "tokens_spent": spent_before[3], "budget": budgets["at kill"]}
    ]
    assert references["before kill"]["budget_events"] == [
        {"task_index": 2, "tokens_spent": spent_before[2], "budget": budgets["before kill"]}
    ]
    for name, (state, trace) in resumed.items():
        assert state["resumes"] == 1
        kinds = [e["kind"] for e in trace["events"]]
        assert kinds.index("interrupted") < kinds.index("resumed") < kinds.index("completed")
        assert _record(state, trace) == references[name], name
