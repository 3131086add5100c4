"""Long runs page: GET /runs/{id} and its trace send one page of decisions with totals;
resume answers with the summary; JSON numbers are rounded, the export stays exact."""

from __future__ import annotations

import json

from fastapi.testclient import TestClient
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.domain.models import Instance, Robot, Task
from app.graph.recorder import DecisionRecord
from app.http.rounding import round_number, rounded
from app.runs import records
from app.runs.spec import RunSpec
from app.store import decision_repository as decision_repo
from app.store.db import make_engine, make_session_factory, transaction
from tests.support.factories import run_row

N_LONG = 10_000
# 0.65 as a sum of floats leaves it: the noise the API must hide and the export must keep.
NOISY = 0.6499999999999999


def _instance(n_tasks: int) -> Instance:
    robots = (
        Robot(name="light", success={"a": 0.9, "b": 0.35}),
        Robot(name="heavy", success={"a": 0.4, "b": 0.85}),
    )
    tasks = tuple(
        Task(id=t, name=f"task{t}", features=("a" if t % 2 else "b",)) for t in range(n_tasks)
    )
    return Instance(tasks=tasks, robots=robots)


def _decision(t: int) -> DecisionRecord:
    robot = t % 2
    return DecisionRecord(
        task_index=t,
        task_id=t,
        task_name=f"task{t}",
        robot=robot,
        robot_name=("light", "heavy")[robot],
        phase="middle",
        expected_success=NOISY,
        reasoning="Rule-based choice: the highest success within the cap.",
        confidence="high",
        tradeoff="none",
        quality=1.0,
        fallback=False,
        attempts=1,
        failure_log=[],
        loads_before=[t // 2, t // 2],
        loads_after=[t // 2 + 1 - robot, t // 2 + robot],
        balance_before=100.0,
        balance_after=-6e-17,
        severity_after="none",
        regret=0.0,
    )


def _stored_run(settings: Settings, run_id: str, n_tasks: int) -> sessionmaker[Session]:
    """A failed run with n_tasks decisions, written through the repository (fast: no graph)."""
    instance = _instance(n_tasks)
    spec = RunSpec.for_instance(instance, mode="balanced", reasoner="rules")
    sessions = make_session_factory(make_engine(settings.db_url))
    with transaction(sessions) as session:
        session.add(
            run_row(
                run_id,
                "failed",
                request=spec.to_json(),
                n_tasks=n_tasks,
                n_robots=2,
                error="stopped for the test",
            )
        )
    with transaction(sessions) as session:
        for t in range(n_tasks):
            decision_repo.upsert_decision(
                session=session, run_id=run_id, values=records.decision_values(_decision(t))
            )
    return sessions


def test_a_10000_task_runs_default_page_is_under_200_kb(
    client: TestClient, settings: Settings
) -> None:
    _stored_run(settings, "long", N_LONG)
    answer = client.get("/runs/long")
    assert answer.status_code == 200
    assert len(answer.content) < 200_000, len(answer.content)
    body = answer.json()
    assert len(body["assignments"]) == 1_000
    assert body["assignments_page"] == {"offset": 0, "limit": 1_000, "total": N_LONG}
    # Totals cover every decision, not the page.
    assert body["progress"]["allocated"] == N_LONG
    assert body["workload"] == {"light": N_LONG // 2, "heavy": N_LONG // 2}

    last = client.get("/runs/long", params={"offset": 9_500, "limit": 1_000}).json()
    assert [a["task_index"] for a in last["assignments"]] == list(range(9_500, N_LONG))
    assert last["assignments_page"] == {"offset": 9_500, "limit": 1_000, "total": N_LONG}


def test_the_trace_pages_decisions_with_their_attempts_and_a_total(
    client: TestClient, settings: Settings
) -> None:
    _stored_run(settings, "paged", 30)
    page = client.get("/runs/paged/trace", params={"offset": 10, "limit": 5}).json()
    assert [d["task_index"] for d in page["decisions"]] == [10, 11, 12, 13, 14]
    assert page["decisions_page"] == {"offset": 10, "limit": 5, "total": 30}
    whole = client.get("/runs/paged/trace").json()
    assert len(whole["decisions"]) == 30 and whole["decisions_page"]["total"] == 30
    beyond = client.get("/runs/paged/trace", params={"offset": 30}).json()
    assert beyond["decisions"] == [] and beyond["decisions_page"]["total"] == 30


def test_page_bounds_are_checked(client: TestClient, settings: Settings) -> None:
    _stored_run(settings, "bounds", 3)
    for params, field in (({"limit": 0}, "limit"), ({"offset": -1}, "offset")):
        answer = client.get("/runs/bounds", params=params)
        assert answer.status_code == 422
        assert answer.json()["detail"][0]["loc"] == ["query", field]
    assert client.get("/runs/bounds", params={"limit": 10_001}).status_code == 422


def test_numbers_are_rounded_in_the_api_and_exact_in_the_export(
    client: TestClient, settings: Settings
) -> None:
    _stored_run(settings, "noisy", 4)
    shown = client.get("/runs/noisy/trace").json()["decisions"][0]
    assert shown["expected_success"] == 0.65
    assert shown["balance_after"] == 0
    assert client.get("/runs/noisy").json()["assignments"][0]["success"] == 0.65
    exported = [
        json.loads(line)
        for line in client.get("/runs/noisy/trace", params={"format": "jsonl"}).text.splitlines()
    ]
    decision = next(line for line in exported if line["type"] == "decision")
    assert decision["expected_success"] == NOISY != 0.65
    assert decision["balance_after"] == -6e-17


def test_resume_answers_with_the_summary_and_a_location(
    client: TestClient, settings: Settings
) -> None:
    _stored_run(settings, "resumable", 40)
    answer = client.post("/runs/resumable/resume")
    assert answer.status_code == 202
    assert answer.headers["location"] == "/runs/resumable"
    body = answer.json()
    assert body["id"] == "resumable" and "assignments" not in body
    assert body["n_tasks"] == 40


def test_rounding_rule() -> None:
    assert round_number(0.6499999999999999) == 0.65
    assert round_number(-6e-17) == 0.0
    assert round_number(123456.78901234567) == 123456.789012
    assert rounded({"a": [1, True, 0.30000000000000004], "b": "x"}) == {
        "a": [1, True, 0.3],
        "b": "x",
    }
