"""Sign-off of completed runs: POST /runs/{id}/signoff, listed by GET /runs/{id}, checked by
trace/verify's signoffs_ok against later edits of the record."""

from __future__ import annotations

import json
import sqlite3
import subprocess
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from pydantic import SecretStr

from app.config import Settings
from app.http.auth import key_fingerprint
from app.store import chain
from tests.support.clients import ClientFactory
from tests.support.offline_check import check_offline
from tests.support.polling import wait_until

CLIENT_KEY = "client-key-7Hq2vN9xLp4Rt8Zw"
SUPERVISOR_KEY = "supervisor:key-Jm3Kd8Qw2Vx6Bn5Y"  # with a colon: the role is after the last
AS_CLIENT = {"Authorization": f"Bearer {CLIENT_KEY}"}
AS_SUPERVISOR = {"Authorization": f"Bearer {SUPERVISOR_KEY}"}
BASELINE = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}
STATEMENT = {"statement": "Plan checked against the site register; approved for shift 2."}
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def secured(make_client: ClientFactory) -> TestClient:
    return make_client(
        api_keys=SecretStr(f"{CLIENT_KEY}:client,{SUPERVISOR_KEY}:supervisor"),
        api_key_names=f"{key_fingerprint(SUPERVISOR_KEY)}=Dana Safety",
    )


def _wait(client: TestClient, run_id: str, status: str) -> None:
    wait_until(client, run_id, (status,), headers=AS_CLIENT)


def _completed(client: TestClient) -> str:
    run_id = str(client.post("/runs", json=BASELINE, headers=AS_CLIENT).json()["id"])
    _wait(client, run_id, "completed")
    return run_id


def test_signoff_records_the_signer_name_and_the_chain_heads(
    secured: TestClient, settings: Settings
) -> None:
    run_id = _completed(secured)
    verify = secured.get(f"/runs/{run_id}/trace/verify", headers=AS_SUPERVISOR).json()
    response = secured.post(f"/runs/{run_id}/signoff", json=STATEMENT, headers=AS_SUPERVISOR)
    assert response.status_code == 201, response.text
    signed = response.json()
    assert signed["signer"] == "Dana Safety"
    assert signed["statement"] == STATEMENT["statement"]
    assert signed["heads"] == verify["heads"]
    assert signed["at"].endswith(("Z", "+00:00"))

    run = secured.get(f"/runs/{run_id}", headers=AS_CLIENT).json()
    assert run["signoffs"] == [signed]
    after = secured.get(f"/runs/{run_id}/trace/verify", headers=AS_SUPERVISOR).json()
    assert after["ok"] is True and after["signoffs_ok"] is True
    assert after["annotations"] == 1 and after["annotations_head"] is not None
    # Signing changes neither chain that it signs; the run's last event is still `completed`.
    assert after["heads"] == verify["heads"] and after["events"] == verify["events"]
    trace = secured.get(f"/runs/{run_id}/trace", headers=AS_SUPERVISOR).json()
    assert trace["events"][-1]["kind"] == "completed"

    # No key is stored anywhere in the database file.
    raw = (settings.data_dir / "ltaa.db").read_bytes()
    assert SUPERVISOR_KEY.encode() not in raw and CLIENT_KEY.encode() not in raw


def test_editing_a_decision_after_signoff_makes_signoffs_ok_false(
    secured: TestClient, settings: Settings
) -> None:
    run_id = _completed(secured)
    assert secured.post(f"/runs/{run_id}/signoff", json=STATEMENT, headers=AS_SUPERVISOR).is_success
    conn = sqlite3.connect(settings.data_dir / "ltaa.db", isolation_level=None)
    try:
        conn.execute(
            "UPDATE decisions SET reasoning = reasoning || ' (amended)' WHERE task_index = 4"
        )
    finally:
        conn.close()
    report = secured.get(f"/runs/{run_id}/trace/verify", headers=AS_SUPERVISOR).json()
    assert report["signoffs_ok"] is False
    assert report["ok"] is False and report["broken"]["task_index"] == 4


def test_rewriting_the_chain_after_signoff_is_caught_by_the_signed_heads(
    secured: TestClient, settings: Settings
) -> None:
    """An insider who recomputes every link still moves the head away from the signed one."""
    run_id = _completed(secured)
    assert secured.post(f"/runs/{run_id}/signoff", json=STATEMENT, headers=AS_SUPERVISOR).is_success
    conn = sqlite3.connect(settings.data_dir / "ltaa.db", isolation_level=None)
    try:
        # A new, validly chained event appended after the sign-off.
        from app.store import chain

        seq, prev = conn.execute(
            "SELECT seq, chain_hash FROM run_events WHERE run_id = ? ORDER BY seq DESC LIMIT 1",
            (run_id,),
        ).fetchone()
        link = chain.event_link(prev, {"seq": seq + 1, "kind": "completed", "detail": {}})
        conn.execute(
            "INSERT INTO run_events (run_id, seq, kind, detail, created_at, chain_hash) "
            "VALUES (?, ?, 'completed', '{}', '2026-01-01 00:00:00', ?)",
            (run_id, seq + 1, link),
        )
    finally:
        conn.close()
    report = secured.get(f"/runs/{run_id}/trace/verify", headers=AS_SUPERVISOR).json()
    assert report["ok"] is True  # the chains alone cannot tell
    assert report["signoffs_ok"] is False  # the signed heads can


def test_signoff_of_a_running_run_is_409_and_a_client_key_is_403(
    make_client: ClientFactory,
) -> None:
    # The run holds at task 3 (the test pause point) until the client closes: running.
    client = make_client(
        api_keys=SecretStr(f"{CLIENT_KEY}:client,{SUPERVISOR_KEY}:supervisor"),
        test_pause="3:reason:before",
    )
    run_id = str(client.post("/runs", json=BASELINE, headers=AS_CLIENT).json()["id"])
    _wait(client, run_id, "running")
    response = client.post(f"/runs/{run_id}/signoff", json=STATEMENT, headers=AS_SUPERVISOR)
    assert response.status_code == 409, response.text
    assert "only a completed run" in response.json()["detail"][0]["msg"].lower()
    client_try = client.post(f"/runs/{run_id}/signoff", json=STATEMENT, headers=AS_CLIENT)
    assert client_try.status_code == 403
    assert client.get(f"/runs/{run_id}", headers=AS_CLIENT).json()["signoffs"] == []


def test_signoff_validates_its_body_and_run(secured: TestClient) -> None:
    run_id = _completed(secured)
    empty = secured.post(f"/runs/{run_id}/signoff", json={"statement": ""}, headers=AS_SUPERVISOR)
    assert empty.status_code == 422 and empty.json()["detail"][0]["loc"] == ["body", "statement"]
    # Only whitespace states nothing either, like an override's reason of only spaces.
    blank = secured.post(
        f"/runs/{run_id}/signoff", json={"statement": " \n\t "}, headers=AS_SUPERVISOR
    )
    assert blank.status_code == 422, blank.text
    assert blank.json()["detail"][0]["loc"] == ["body", "statement"]
    # A field this body does not have (a typo, or a signer the key does not name) is refused.
    extra = secured.post(
        f"/runs/{run_id}/signoff", json={**STATEMENT, "signer": "someone"}, headers=AS_SUPERVISOR
    )
    assert extra.status_code == 422 and extra.json()["detail"][0]["loc"] == ["body", "signer"]
    assert secured.get(f"/runs/{run_id}", headers=AS_CLIENT).json()["signoffs"] == []
    missing = secured.post(f"/runs/{'0' * 32}/signoff", json=STATEMENT, headers=AS_SUPERVISOR)
    assert missing.status_code == 404


def test_signoff_honours_an_idempotency_key(secured: TestClient) -> None:
    run_id = _completed(secured)
    headers = {**AS_SUPERVISOR, "Idempotency-Key": "signoff-1"}
    first = secured.post(f"/runs/{run_id}/signoff", json=STATEMENT, headers=headers)
    again = secured.post(f"/runs/{run_id}/signoff", json=STATEMENT, headers=headers)
    assert first.status_code == again.status_code == 201
    assert again.json() == first.json() and again.headers["Idempotent-Replayed"] == "true"
    other = secured.post(f"/runs/{run_id}/signoff", json={"statement": "x"}, headers=headers)
    assert other.status_code == 409
    assert len(secured.get(f"/runs/{run_id}", headers=AS_CLIENT).json()["signoffs"]) == 1


def _export(client: TestClient, run_id: str) -> list[dict[str, Any]]:
    response = client.get(
        f"/runs/{run_id}/trace", params={"format": "jsonl"}, headers=AS_SUPERVISOR
    )
    assert response.status_code == 200, response.text
    return [json.loads(line) for line in response.text.splitlines()]


def _offline(lines: list[dict[str, Any]], path: Path) -> subprocess.CompletedProcess[str]:
    """The offline check the README points to, run on an export as a file."""
    path.write_text("".join(json.dumps(line, ensure_ascii=False) + "\n" for line in lines))
    return check_offline(path)


def _signed_off_and_reported(client: TestClient) -> tuple[str, dict[str, Any]]:
    run_id = _completed(client)
    signed = client.post(f"/runs/{run_id}/signoff", json=STATEMENT, headers=AS_SUPERVISOR)
    assert signed.status_code == 201, signed.text
    reported = client.post(
        f"/runs/{run_id}/execution",
        json={"updates": [{"task_id": 0, "state": "started"}]},
        headers=AS_CLIENT,
    )
    assert reported.status_code == 200, reported.text
    return run_id, signed.json()


def test_the_export_carries_the_annotation_chain_and_verifies_offline(
    secured: TestClient, tmp_path: Path
) -> None:
    run_id, signed = _signed_off_and_reported(secured)
    lines = _export(secured, run_id)
    annotations = [line for line in lines if line["type"] == "annotation"]
    assert [(a["seq"], a["kind"]) for a in annotations] == [
        (1, "signoff"),
        (2, "execution_reported"),
    ]
    # After the decisions, before `end`, which counts them.
    assert [line["type"] for line in lines[-3:]] == ["annotation", "annotation", "end"]
    assert lines[-1]["annotations"] == 2
    signoff = annotations[0]["detail"]
    assert (signoff["statement"], signoff["heads"]) == (signed["statement"], signed["heads"])
    verify = secured.get(f"/runs/{run_id}/trace/verify", headers=AS_SUPERVISOR).json()
    assert annotations[-1]["chain_hash"] == verify["annotations_head"]
    assert verify["ok"] is True and verify["annotations"] == 2

    checked = _offline(lines, tmp_path / "run.jsonl")
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert verify["annotations_head"] in checked.stdout


def test_a_tampered_annotation_line_fails_the_offline_check(
    secured: TestClient, tmp_path: Path
) -> None:
    run_id, _ = _signed_off_and_reported(secured)
    lines = _export(secured, run_id)
    first = next(i for i, line in enumerate(lines) if line["type"] == "annotation")

    edited = [dict(line) for line in lines]
    edited[first]["detail"] = {**edited[first]["detail"], "statement": "Approved for all shifts."}
    checked = _offline(edited, tmp_path / "edited.jsonl")
    assert checked.returncode == 1, checked.stdout
    assert "broken at annotation 1" in checked.stdout

    dropped = [line for i, line in enumerate(lines) if i != first]
    checked = _offline(dropped, tmp_path / "dropped.jsonl")
    assert checked.returncode == 1, checked.stdout

    # A sign-off whose heads are not the record's (its hash recomputed to match) is caught
    # as well: what was signed is not what the record says.
    forged = [dict(line) for line in lines]
    heads = dict(forged[first]["detail"]["heads"])
    heads["decisions"] = "f" * 64
    forged[first]["detail"] = {**forged[first]["detail"], "heads": heads}
    prev = chain.genesis("annotations", run_id)
    for line in forged:
        if line["type"] == "annotation":
            line["chain_hash"] = prev = chain.annotation_link(prev, line)
    checked = _offline(forged, tmp_path / "forged.jsonl")
    assert checked.returncode == 1, checked.stdout
    assert "sign-off" in checked.stdout
