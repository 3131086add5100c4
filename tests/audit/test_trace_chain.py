"""Tamper-evident traces: GET /runs/{id}/trace/verify and GET /runs/{id}/trace?format=jsonl.

Tampering is done the way an insider would: straight in the SQLite file with sqlite3, behind
the service's back, while the service keeps running.
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterator
from datetime import datetime, timedelta
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import create_engine
from sqlalchemy.orm import sessionmaker

from app.audit import record_pages
from app.audit.export import trace_record
from app.audit.verify import verify_trace
from app.config import Settings
from app.http.rounding import rounded
from app.runs import records
from app.store import chain
from app.store import decision_repository as decision_repo
from app.store.models import Attempt, Decision, RunEvent
from tests.support.polling import eventually

BASELINE = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}
N_TASKS = 36


def _completed_run(client: TestClient, body: dict[str, Any] = BASELINE) -> str:
    run_id = str(client.post("/runs", json=body).json()["id"])
    eventually(
        lambda: client.get(f"/runs/{run_id}").json()["status"],
        until=_completed,
        what=f"run {run_id} completed",
    )
    return run_id


def _completed(status: str) -> bool:
    if status != "completed":
        assert status in ("queued", "running"), status
    return status == "completed"


def _verify(client: TestClient, run_id: str) -> dict[str, Any]:
    response = client.get(f"/runs/{run_id}/trace/verify")
    assert response.status_code == 200, response.text
    return dict(response.json())


def _jsonl(client: TestClient, run_id: str) -> list[dict[str, Any]]:
    response = client.get(f"/runs/{run_id}/trace", params={"format": "jsonl"})
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "application/x-ndjson"
    return [json.loads(line) for line in response.text.splitlines()]


@pytest.fixture
def db(settings: Settings) -> Iterator[sqlite3.Connection]:
    """A second, raw connection to the service's own database file."""
    conn = sqlite3.connect(settings.data_dir / "ltaa.db", isolation_level=None)
    yield conn
    conn.close()


def test_a_completed_run_verifies_ok_and_reports_its_chain_heads(client: TestClient) -> None:
    run_id = _completed_run(client)
    report = _verify(client, run_id)
    lines = _jsonl(client, run_id)
    decisions = [line for line in lines if line["type"] == "decision"]
    events = [line for line in lines if line["type"] == "event"]
    assert report == {
        "ok": True,
        "decisions": N_TASKS,
        "events": 3,
        "annotations": 0,
        "annotations_head": None,
        "signoffs_ok": True,
        "parent": None,
        "unchained": 0,
        "broken": None,
        "heads": {"decisions": decisions[-1]["chain_hash"], "events": events[-1]["chain_hash"]},
        "chain_scheme": "ltaa-trace-chain/v2",
        "signature": None,  # no server signing key here
    }
    # Every row carries its own link: no two hashes alike, all of them SHA-256 hex.
    hashes = [line["chain_hash"] for line in decisions + events]
    assert len(set(hashes)) == len(hashes) and all(len(h) == 64 for h in hashes)


# Each tampering as SQL run behind the service's back, and where verify must say it broke.
TAMPERING: dict[str, tuple[list[str], str, int, str]] = {
    "robot of a decision edited": (
        ["UPDATE decisions SET robot = (robot + 1) % 3, robot_name = 'heavy' WHERE task_index = 7"],
        "decisions",
        7,
        "does not match its recorded hash",
    ),
    "reasoning of a decision edited": (
        ["UPDATE decisions SET reasoning = reasoning || ' (approved)' WHERE task_index = 20"],
        "decisions",
        20,
        "does not match its recorded hash",
    ),
    "an attempt's reply edited": (
        [
            "UPDATE attempts SET reply_text = replace(reply_text, 'Decision', 'Decisión') "
            "WHERE task_index = 3"
        ],
        "decisions",
        3,
        "one of its task's attempts",
    ),
    "an attempt's verdict edited": (
        ["UPDATE attempts SET quality = 0.99, accepted = 1 WHERE task_index = 30"],
        "decisions",
        30,
        "does not match",
    ),
    "a decision deleted": (
        ["DELETE FROM decisions WHERE task_index = 10"],
        "decisions",
        10,
        "is missing",
    ),
    "the last decision deleted": (
        [f"DELETE FROM decisions WHERE task_index = {N_TASKS - 1}"],
        "decisions",
        N_TASKS - 1,
        "the last decisions were deleted",
    ),
    "two decisions swapped": (
        [
            "UPDATE decisions SET task_index = -1 WHERE task_index = 4",
            "UPDATE decisions SET task_index = 4 WHERE task_index = 5",
            "UPDATE decisions SET task_index = 5 WHERE task_index = -1",
        ],
        "decisions",
        4,
        "does not match",
    ),
    "two decisions' robots swapped": (
        [
            "UPDATE decisions SET robot = CASE task_index WHEN 2 THEN (SELECT robot FROM "
            "decisions WHERE task_index = 3) ELSE (SELECT robot FROM decisions WHERE "
            "task_index = 2) END WHERE task_index IN (2, 3)"
        ],
        "decisions",
        2,
        "does not match",
    ),
    "a decision's hash erased": (
        ["UPDATE decisions SET chain_hash = NULL WHERE task_index = 15"],
        "decisions",
        15,
        "has no chain hash",
    ),
    "an event's detail edited": (
        ["UPDATE run_events SET detail = json_set(detail, '$.tasks', 35) WHERE seq = 2"],
        "events",
        2,
        "does not match",
    ),
    "an event deleted": (["DELETE FROM run_events WHERE seq = 2"], "events", 2, "is missing"),
    "the last event deleted": (
        ["DELETE FROM run_events WHERE seq = 3"],
        "events",
        3,
        "do not end with the 'completed' event",
    ),
    "two events swapped": (
        [
            "UPDATE run_events SET seq = -1 WHERE seq = 1",
            "UPDATE run_events SET seq = 1 WHERE seq = 2",
            "UPDATE run_events SET seq = 2 WHERE seq = -1",
        ],
        "events",
        1,
        "does not match",
    ),
}


@pytest.mark.parametrize("case", list(TAMPERING))
def test_verify_finds_the_first_tampered_row(
    client: TestClient, db: sqlite3.Connection, case: str
) -> None:
    statements, table, key, reason = TAMPERING[case]
    run_id = _completed_run(client)
    before = _verify(client, run_id)
    assert before["ok"] is True
    for sql in statements:  # the only run in this database
        assert db.execute(sql).rowcount >= 1, sql

    report = _verify(client, run_id)
    assert report["ok"] is False
    broken = report["broken"]
    assert broken["table"] == table, broken
    assert broken["task_index" if table == "decisions" else "seq"] == key, broken
    assert reason in broken["reason"], broken
    if "does not match" in reason:
        # The row is there with its original hash; the content no longer produces it.
        assert broken["stored"] is not None and broken["expected"] != broken["stored"]
    # The other chain is untouched and does not hide the break.
    other = "events" if table == "decisions" else "decisions"
    assert report[other] == before[other]
    assert report["heads"][other] == before["heads"][other]


def test_rows_written_before_chaining_are_unchained_not_ok(
    client: TestClient,
    db: sqlite3.Connection,
) -> None:
    run_id = _completed_run(client)
    db.execute("UPDATE decisions SET chain_hash = NULL WHERE run_id = ?", (run_id,))
    db.execute("UPDATE run_events SET chain_hash = NULL WHERE run_id = ?", (run_id,))
    report = _verify(client, run_id)
    assert report["ok"] is False
    assert report["unchained"] == N_TASKS + 3
    assert report["heads"] == {"decisions": None, "events": None}
    assert report["broken"]["table"] == "decisions" and report["broken"]["task_index"] == 0
    assert "written before tamper evidence existed" in report["broken"]["reason"]


def test_a_decision_upserted_again_with_the_same_content_keeps_its_hash(
    client: TestClient,
    settings: Settings,
) -> None:
    """What happens when the store node re-runs after a crash: the same decision is upserted
    again (with a new created_at); its link, and so every later link, must not change."""
    run_id = _completed_run(client)
    before = _verify(client, run_id)
    sessions = sessionmaker(create_engine(settings.db_url), expire_on_commit=False)
    with sessions() as session, session.begin():
        rows = decision_repo.decisions(session=session, run_id=run_id)
        stored = {d.task_index: d.chain_hash for d in rows}
        for row in (rows[0], rows[17], rows[-1]):
            decision_repo.upsert_decision(
                session=session,
                run_id=run_id,
                values=records.decision_values(records.decision_record(row)),
            )
    with sessions() as session:
        again = {
            d.task_index: d.chain_hash
            for d in decision_repo.decisions(session=session, run_id=run_id)
        }
    assert again == stored
    assert _verify(client, run_id) == before


def test_jsonl_streams_the_whole_record_line_by_line(client: TestClient) -> None:
    run_id = _completed_run(client)
    trace = client.get(f"/runs/{run_id}/trace", params={"include": "prompts"}).json()
    lines = _jsonl(client, run_id)

    assert [line["type"] for line in lines] == (
        ["run"] + ["event"] * 3 + ["decision"] * N_TASKS + ["end"]
    )
    header, end = lines[0], lines[-1]
    assert header["id"] == run_id and header["status"] == "completed"
    assert header["n_tasks"] == N_TASKS and header["request"]["reasoner"] == "rules"
    assert end == {
        "type": "end",
        "events": 3,
        "decisions": N_TASKS,
        "attempts": N_TASKS,
        "annotations": 0,
    }

    events = [line for line in lines if line["type"] == "event"]
    assert [(e["seq"], e["kind"], e["detail"]) for e in events] == [
        (e["seq"], e["kind"], e["detail"]) for e in trace["events"]
    ]
    # Times carry their offset (SQLite hands them back naive; they are UTC).
    for line in [header, *events, *(line for line in lines if line["type"] == "decision")]:
        assert datetime.fromisoformat(
            line.get("at") or line["created_at"]
        ).utcoffset() == timedelta(0)
    decisions = [line for line in lines if line["type"] == "decision"]
    assert [d["task_index"] for d in decisions] == list(range(N_TASKS))
    for line, shown in zip(decisions, trace["decisions"], strict=True):
        assert line["robot_name"] == shown["robot"]
        # The export is exact (hashes are computed on it); the API rounds its numbers.
        assert line["reasoning"] == shown["reasoning"]
        assert rounded(line["regret"]) == shown["regret"]
        records = line["attempt_records"]
        assert len(records) == len(shown["attempts"]) >= 1
        assert records[0]["user_prompt"] == shown["attempts"][0]["user_prompt"]
        assert records[0]["reply_text"] == shown["attempts"][0]["reply"]
        assert (
            records[0]["system_prompt"]
            and rounded(records[0]["scores"]) == (shown["attempts"][0]["scores"])
        )


def test_the_jsonl_export_alone_suffices_to_recompute_both_chains(client: TestClient) -> None:
    """An auditor holding only the export can check it, with the genesis it names."""
    run_id = _completed_run(client)
    lines = _jsonl(client, run_id)
    prev = dict(lines[0]["genesis"])
    for line in lines[1:-1]:
        if line["type"] == "event":
            assert chain.event_link(prev["events"], line) == line["chain_hash"]
            prev["events"] = line["chain_hash"]
        else:
            digest = chain.attempts_digest(line["attempt_records"])
            assert chain.decision_link(prev["decisions"], line, digest) == line["chain_hash"]
            prev["decisions"] = line["chain_hash"]
    assert prev == _verify(client, run_id)["heads"]


def test_the_record_is_read_in_pages_with_nothing_lost_at_page_boundaries(
    client: TestClient,
    settings: Settings,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    run_id = _completed_run(client)
    monkeypatch.setattr(record_pages, "DECISIONS_PER_PAGE", 5)
    monkeypatch.setattr(record_pages, "EVENTS_PER_PAGE", 2)
    sessions = sessionmaker(create_engine(settings.db_url), expire_on_commit=False)
    pages = list(trace_record(sessions=sessions, run_id=run_id))
    # run, events 1-2, event 3, decisions in 8 pages (5 x 7 + 1), end
    assert [len(p) for p in pages] == [1, 2, 1, *[5] * 7, 1, 1]
    decisions = [line["task_index"] for p in pages for line in p if line["type"] == "decision"]
    assert decisions == list(range(N_TASKS))
    assert _verify(client, run_id)["ok"] is True
    assert verify_trace(sessions=sessions, run_id=run_id).ok


def test_unknown_runs_and_formats_are_4xx_in_the_one_error_shape(client: TestClient) -> None:
    for path, params in [
        ("/runs/nope/trace/verify", {}),
        ("/runs/nope/trace", {"format": "jsonl"}),
    ]:
        response = client.get(path, params=params)
        assert response.status_code == 404
        assert response.json()["detail"][0]["loc"] == ["path", "run_id"]
    run_id = _completed_run(client)
    response = client.get(f"/runs/{run_id}/trace", params={"format": "csv"})
    assert response.status_code == 422
    (error,) = response.json()["detail"]
    assert error["loc"] == ["query", "format"] and "jsonl" in error["msg"]
    # format=json is the default and unchanged.
    assert (
        client.get(f"/runs/{run_id}/trace", params={"format": "json"}).json()
        == client.get(f"/runs/{run_id}/trace").json()
    )


def test_the_openapi_documents_both_trace_media_types_and_the_verify_shape(
    client: TestClient,
) -> None:
    spec = client.get("/openapi.json").json()
    trace = spec["paths"]["/runs/{run_id}/trace"]["get"]
    assert set(trace["responses"]["200"]["content"]) == {"application/json", "application/x-ndjson"}
    params = {p["name"]: p for p in trace["parameters"]}
    assert params["format"]["schema"]["enum"] == ["json", "jsonl"]
    verify = spec["paths"]["/runs/{run_id}/trace/verify"]["get"]
    assert verify["responses"]["200"]["content"]["application/json"]["schema"] == {
        "$ref": "#/components/schemas/TraceVerifyOut"
    }
    assert {"401", "403", "404", "422"} <= set(verify["responses"])


def test_every_audited_column_is_in_the_chain() -> None:
    """A column added later must be hashed, or deliberately left out here."""

    def columns(model: Any) -> set[str]:
        return {c.name for c in model.__table__.columns}

    # The pin and time columns are hashed too, only when set (so links written before them
    # hold).
    hashed = (
        set(chain.DECISION_FIELDS)
        | set(chain.PIN_FIELDS)
        | set(chain.TIME_FIELDS)
        | set(chain.TEAM_FIELDS)
    )
    assert hashed == columns(Decision) - {
        "id",
        "run_id",
        "created_at",
        "chain_hash",
    }
    assert set(chain.ATTEMPT_FIELDS) == columns(Attempt) - {
        "id",
        "run_id",
        "task_index",
        "created_at",
    }
    assert set(chain.EVENT_FIELDS) == columns(RunEvent) - {
        "id",
        "run_id",
        "created_at",
        "chain_hash",
    }
