"""Durable LTAA runs with team tasks (docs/allocation.md#teams): an untimed team run completes
with valid teams, its trace lists each team decision's members, the chain verifies online and
offline (and the members are in it), a guided run reaches the exact optimum, and a timed team run
plans in time as /allocate does (reviews of team decisions: tests/reviews/test_team_reviews.py)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.allocation.test_api_teams import TEAM_BODY
from tests.audit.test_docs_check_trace import check_trace_source
from tests.fakes.llm_providers import PROVIDERS
from tests.support.clients import ClientFactory
from tests.support.offline_check import check_offline
from tests.support.polling import wait_until

SKILLS = {"crane": {"heavy"}}


def completed(client: TestClient, **changes: Any) -> dict[str, Any]:
    created = client.post("/runs", json={**copy.deepcopy(TEAM_BODY), **changes})
    assert created.status_code == 202, created.text
    state = wait_until(client, created.json()["id"], timeout=120)
    assert state["status"] == "completed", state
    return state


def check_teams(assignments: list[dict[str, Any]]) -> dict[str, int]:
    """Every unit covered by a distinct robot that may cover it; the loads, counting members."""
    loads = {r["name"]: 0 for r in TEAM_BODY["robots"]}
    for task, a in zip(TEAM_BODY["tasks"], assignments, strict=True):
        if "team" in task:
            members = a["team"]
            units = [f for f, c in task["team"].items() for _ in range(c)]
            assert [m["feature"] for m in members] == units, a
            robots = [m["robot"] for m in members]
            assert len(set(robots)) == len(robots), a
            assert robots[0] == a["robot"], "robot is the first unit's member"
            for m in members:
                assert m["feature"] in SKILLS.get(m["robot"], {m["feature"]}), m
        else:
            assert "team" not in a or a["team"] is None
            robots = [a["robot"]]
        for name in robots:
            loads[name] += 1
    return loads


def test_a_durable_team_run_lists_members_and_verifies(
    any_db_client: TestClient, tmp_path: Path
) -> None:
    client = any_db_client
    state = completed(client, reasoner="rules")
    run_id = state["id"]
    run = client.get(f"/runs/{run_id}").json()
    loads = check_teams(run["assignments"])
    assert run["workload"] == loads and sum(loads.values()) == 6
    assert all(1 <= x <= 3 for x in loads.values()), loads  # balanced: W 2, cap 1
    trace = client.get(f"/runs/{run_id}/trace").json()
    members = {d["task_index"]: d.get("team") for d in trace["decisions"]}
    assert [len(members[t] or []) for t in range(4)] == [2, 2, 0, 0]
    assert {d["task_index"]: d["team"] for d in run["assignments"] if d.get("team")} == {
        t: m for t, m in members.items() if m
    }
    verify = client.get(f"/runs/{run_id}/trace/verify").json()
    assert verify["ok"], verify

    export = tmp_path / "run.jsonl"
    export.write_text(client.get(f"/runs/{run_id}/trace", params={"format": "jsonl"}).text)
    script = tmp_path / "check_trace.py"
    script.write_text(check_trace_source())
    assert check_offline(export, script=script).returncode == 0
    # The members are in the chain: swapping a member breaks it offline.
    lines = export.read_text().splitlines()
    at = next(i for i, x in enumerate(lines) if json.loads(x).get("team"))
    edited = json.loads(lines[at])
    edited["team"][1]["robot"] = "arm" if edited["team"][1]["robot"] != "arm" else "lifter"
    lines[at] = json.dumps(edited)
    export.write_text("\n".join(lines) + "\n")
    broken = check_offline(export, script=script)
    assert broken.returncode == 1 and "decision" in broken.stdout + broken.stderr


def test_a_guided_team_run_reaches_the_exact_optimum(client: TestClient) -> None:
    optimal = client.post(
        "/allocate", json={**copy.deepcopy(TEAM_BODY), "solver": "optimal", "mode": "balanced"}
    ).json()
    state = completed(client, reasoner="rules", guidance="optimizer")
    run = client.get(f"/runs/{state['id']}").json()
    check_teams(run["assignments"])
    assert run["regret"] == 0.0
    best = optimal["metrics"]["expected_success"]
    assert abs(run["metrics"]["expected_success"] - best) < 1e-9
    by_task = {a["task_index"]: a.get("team") for a in run["assignments"]}
    assert [by_task[t] for t in range(4)] == [a.get("team") for a in optimal["assignments"]]


def test_a_durable_timed_team_run_plans_as_allocate_and_shows_teams_in_every_lane(
    client: TestClient,
) -> None:
    """docs/schedules.md#runs-in-time with team tasks: a durable run decides in time as the
    synchronous solver does (same teams, same times), and its schedule puts each team task in
    every member's lane over the same minutes."""
    from tests.allocation.test_api_timed_teams import TIMED_TEAM_BODY

    body = copy.deepcopy(TIMED_TEAM_BODY)
    created = client.post("/runs", json={**body, "reasoner": "rules"})
    assert created.status_code == 202, created.text
    state = wait_until(client, created.json()["id"], timeout=120)
    assert state["status"] == "completed", state
    run = client.get(f"/runs/{state['id']}").json()
    sync = client.post("/allocate", json={**body, "solver": "ltaa"}).json()
    keys = ("task_id", "robot", "team", "start", "end")
    assert [{k: a.get(k) for k in keys} for a in run["assignments"]] == [
        {k: a.get(k) for k in keys} for a in sync["assignments"]
    ]
    schedule = client.get(f"/runs/{state['id']}/schedule").json()
    for a in run["assignments"]:
        for m in a.get("team") or []:
            lane = schedule["robots"][m["robot"]]["lane"]
            worked = [
                (i["start"], i["end"])
                for i in lane
                if i["kind"] == "task" and i["task_id"] == a["task_id"]
            ]
            assert worked == [(a["start"], a["end"])], (a["task_id"], m)
    trace = client.get(f"/runs/{state['id']}/trace").json()
    teams = {d["task_id"]: d.get("team") for d in trace["decisions"]}
    assert teams["beam"] and teams["panel"] and not teams["sweep"]
    # The console's run page draws the Gantt chart with the team's bars in each lane.
    page = client.get(f"/console/runs/{state['id']}")
    assert page.status_code == 200 and f"makespan of {schedule['makespan']:,.0f} min" in page.text


def test_a_guided_timed_team_run_follows_its_stored_plans_teams_and_replays(
    client: TestClient,
) -> None:
    """docs/schedules.md#teams-in-a-run-in-time: the plan (the exact team schedule) is stored
    with its teams in `guidance_planned`; the guided run forms those teams; a replay of the run
    reproduces its plan, teams and times included."""
    from tests.allocation.test_api_timed_teams import TIMED_TEAM_BODY

    body = {**copy.deepcopy(TIMED_TEAM_BODY), "reasoner": "rules", "guidance": "optimizer"}
    created = client.post("/runs", json=body)
    assert created.status_code == 202, created.text
    run_id = created.json()["id"]
    state = wait_until(client, run_id, timeout=120)
    assert state["status"] == "completed", state
    events = client.get(f"/runs/{run_id}/trace").json()["events"]
    (planned,) = [e["detail"] for e in events if e["kind"] == "guidance_planned"]
    plan = planned.get("plan", planned)
    names = [r["name"] for r in TIMED_TEAM_BODY["robots"]]
    run = client.get(f"/runs/{run_id}").json()
    by_index = {a["task_index"]: a for a in run["assignments"]}
    assert set(plan["teams"]) == {"0", "1"}
    for t, members in plan["teams"].items():
        assert [m["robot"] for m in by_index[int(t)]["team"]] == [names[r] for r in members]
    assert [a["start"] for a in run["assignments"]] == [
        plan["starts"][a["task_index"]] for a in run["assignments"]
    ]
    replay = client.post("/runs", json={"reasoner": "replay", "replay_of": run_id})
    assert replay.status_code == 202, replay.text
    again = wait_until(client, replay.json()["id"], timeout=120)
    assert again["status"] == "completed", again
    keys = ("task_id", "robot", "team", "start", "end")
    replayed = client.get(f"/runs/{replay.json()['id']}").json()["assignments"]
    assert [{k: a.get(k) for k in keys} for a in replayed] == [
        {k: a.get(k) for k in keys} for a in run["assignments"]
    ]


def test_a_durable_timed_team_run_over_an_sdk_forms_the_rules_teams(
    make_client: ClientFactory,
) -> None:
    """The OpenAI-compatible SDK against its loopback fake on a timed team instance: the fake
    reads the timed team prompt (each robot's time, each candidate team's start and end) and
    answers as the rules do, every answer accepted at the first attempt."""
    from tests.allocation.test_api_timed_teams import TIMED_TEAM_BODY

    provider = PROVIDERS["openai"]
    with provider.fake() as api:
        client = make_client(**provider.settings(api))
        body = {**copy.deepcopy(TIMED_TEAM_BODY), "reasoner": "openai"}
        created = client.post("/runs", json=body)
        assert created.status_code == 202, created.text
        state = wait_until(client, created.json()["id"], timeout=120)
        assert state["status"] == "completed", state
        assert len(api.requests) == 4  # one call per decision
        rules = client.post("/runs", json={**body, "reasoner": "rules"}).json()["id"]
        assert wait_until(client, rules, timeout=120)["status"] == "completed"
    keys = ("task_id", "robot", "team", "start", "end")
    by_sdk, by_rules = (
        [{k: a.get(k) for k in keys} for a in client.get(f"/runs/{i}").json()["assignments"]]
        for i in (state["id"], rules)
    )
    assert by_sdk == by_rules


@pytest.mark.parametrize("name", list(PROVIDERS))
def test_a_durable_llm_team_run_forms_teams_and_replays(
    make_client: ClientFactory, name: str
) -> None:
    provider = PROVIDERS[name]
    with provider.fake() as api:
        client = make_client(**provider.settings(api))
        state = completed(client, reasoner=name)
        assert len(api.requests) == 4  # one call per decision: every team answer accepted
    run = client.get(f"/runs/{state['id']}").json()
    check_teams(run["assignments"])
    trace = client.get(f"/runs/{state['id']}/trace").json()
    assert all(not d["fallback"] and d["reasoner"] == name for d in trace["decisions"])
    reference = client.get(f"/runs/{completed(client, reasoner='rules')['id']}").json()
    assert run["assignments"] == reference["assignments"]  # the fakes answer as the rules do
    replay = completed(client, reasoner="replay", replay_of=state["id"])
    assert client.get(f"/runs/{replay['id']}").json()["assignments"] == run["assignments"]
