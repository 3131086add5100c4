"""Signed heads: with a server key, a completed run's chain heads are signed; a record
rewritten with every hash recomputed by the public chain functions fails on its signature
(API and the offline script); retired keys and the old chain scheme still verify."""

from __future__ import annotations

import json
import time
from pathlib import Path

from fastapi.testclient import TestClient
from sqlalchemy import update
from sqlalchemy.orm import Session, sessionmaker

from app.audit.signing import generate_key_file
from app.config import Settings
from app.main import create_app
from app.store import chain
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import make_engine, make_session_factory, transaction
from app.store.models import Decision, Run, RunSignature
from tests.support.factories import run_row
from tests.support.offline_check import check_offline
from tests.support.polling import eventually

ROOT = Path(__file__).resolve().parents[2]


def _signed_settings(settings: Settings, tmp_path: Path, name: str = "key.pem") -> Settings:
    generate_key_file(tmp_path / name)
    return settings.model_copy(update={"signing_key_file": tmp_path / name})


def _completed(client: TestClient) -> str:
    run_id = str(
        client.post("/runs", json={"scenario": "baseline", "reasoner": "rules"}).json()["id"]
    )
    for _ in range(600):
        if client.get(f"/runs/{run_id}").json()["status"] == "completed":
            return run_id
        time.sleep(0.05)
    raise AssertionError("run did not complete")


def _sessions(settings: Settings) -> sessionmaker[Session]:
    return make_session_factory(make_engine(settings.db_url))


def _rechain_decisions(sessions: sessionmaker[Session], run_id: str) -> None:
    """What a database writer who read the code can do: recompute every decision link
    from the genesis with the public chain functions."""
    with transaction(sessions) as session:
        run = session.get(Run, run_id)
        assert run is not None
        prev = chain.run_genesis(
            "decisions",
            run_id,
            scheme=run.chain_scheme,
            request=run.request,
            mode=run.mode,
            max_deviation=run.max_deviation,
        )
        by_task = decision_repo.attempts_of_tasks(
            session=session, run_id=run_id, first=0, last=10**6
        )
        for d in decision_repo.decisions(session=session, run_id=run_id):
            attempts = [
                {name: getattr(a, name) for name in chain.ATTEMPT_FIELDS}
                for a in by_task.get(d.task_index, [])
            ]
            values = {name: getattr(d, name) for name in chain.DECISION_FIELDS}
            d.chain_hash = chain.decision_link(prev, values, chain.attempts_digest(attempts))
            prev = d.chain_hash


def _export(client: TestClient, run_id: str, path: Path) -> Path:
    path.write_text(client.get(f"/runs/{run_id}/trace", params={"format": "jsonl"}).text)
    return path


def _public_key_file(client: TestClient, path: Path) -> Path:
    path.write_text(client.get("/audit/public-key").json()["current"]["public_key_pem"])
    return path


def test_a_completed_run_is_signed_and_verifies(settings: Settings, tmp_path: Path) -> None:
    signed = _signed_settings(settings, tmp_path)
    with TestClient(create_app(signed)) as client:
        run_id = _completed(client)
        verify = client.get(f"/runs/{run_id}/trace/verify").json()
        keys = client.get("/audit/public-key").json()
        export = _export(client, run_id, tmp_path / "run.jsonl")
        pem = _public_key_file(client, tmp_path / "public.pem")
    assert verify["ok"] is True and verify["chain_scheme"] == chain.SCHEME_V2
    assert verify["signature"] == {
        "key_id": keys["current"]["key_id"],
        "reason": "completed",
        "valid": True,
        "problem": None,
    }
    assert keys["algorithm"] == "Ed25519" and keys["retired"] == []
    checked = check_offline(export, pem)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert "signature ok" in checked.stdout


def test_a_rewritten_and_rehashed_record_fails_on_its_signature(
    settings: Settings, tmp_path: Path
) -> None:
    signed = _signed_settings(settings, tmp_path)
    with TestClient(create_app(signed)) as client:
        run_id = _completed(client)
        pem = _public_key_file(client, tmp_path / "public.pem")
        sessions = _sessions(signed)
        with transaction(sessions) as session:
            session.execute(
                update(Decision)
                .where(Decision.run_id == run_id, Decision.task_index == 5)
                .values(reasoning="rewritten after the fact")
            )
        _rechain_decisions(sessions, run_id)
        verify = client.get(f"/runs/{run_id}/trace/verify").json()
        export = _export(client, run_id, tmp_path / "forged.jsonl")
        # The forger also puts the new heads into the signed payload: the signature breaks.
        with transaction(sessions) as session:
            row = session.query(RunSignature).filter_by(run_id=run_id).one()
            row.payload = {
                **row.payload,
                "heads": {**row.payload["heads"], "decisions": verify["heads"]["decisions"]},
            }
        reforged = client.get(f"/runs/{run_id}/trace/verify").json()
        export2 = _export(client, run_id, tmp_path / "reforged.jsonl")
    assert verify["broken"] is None  # every link recomputed: the chains alone pass
    assert verify["ok"] is False and verify["signature"]["valid"] is False
    assert "differ from the signed ones" in verify["signature"]["problem"]
    offline = check_offline(export, pem)
    assert offline.returncode == 1 and "bad signature" in offline.stdout
    assert reforged["ok"] is False and "bad signature" in reforged["signature"]["problem"]
    offline2 = check_offline(export2, pem)
    assert offline2.returncode == 1 and "bad signature" in offline2.stdout


def test_a_run_signed_with_a_retired_key_still_verifies(settings: Settings, tmp_path: Path) -> None:
    old = _signed_settings(settings, tmp_path, "old.pem")
    with TestClient(create_app(old)) as client:
        run_id = _completed(client)
        retired = tmp_path / "retired"
        retired.mkdir()
        _public_key_file(client, retired / "old.pub.pem")
    generate_key_file(tmp_path / "new.pem")
    rotated = old.model_copy(
        update={"signing_key_file": tmp_path / "new.pem", "retired_public_keys_dir": retired}
    )
    with TestClient(create_app(rotated)) as client:
        keys = client.get("/audit/public-key").json()
        verify = client.get(f"/runs/{run_id}/trace/verify").json()
    assert (
        len(keys["retired"]) == 1 and keys["retired"][0]["key_id"] == verify["signature"]["key_id"]
    )
    assert keys["current"]["key_id"] != verify["signature"]["key_id"]
    assert verify["ok"] is True and verify["signature"]["valid"] is True


def test_a_run_written_under_the_old_chain_scheme_still_verifies(
    client: TestClient, settings: Settings, tmp_path: Path
) -> None:
    sessions = _sessions(settings)
    with transaction(sessions) as session:
        # As the release before chain_scheme wrote it: no scheme recorded, v1 geneses.
        session.add(run_row("legacy", "failed", n_tasks=2))
    with transaction(sessions) as session:
        repo.add_event(session=session, run_id="legacy", kind="created", detail={})
        repo.add_event(session=session, run_id="legacy", kind="failed", detail={})
    verify = client.get("/runs/legacy/trace/verify").json()
    assert verify["ok"] is True and verify["chain_scheme"] == chain.SCHEME
    assert verify["signature"] is None and verify["events"] == 2
    export = _export(client, "legacy", tmp_path / "legacy.jsonl")
    assert check_offline(export).returncode == 0


def test_the_v2_genesis_covers_the_runs_immutable_fields(
    client: TestClient, settings: Settings
) -> None:
    run_id = _completed(client)
    with transaction(_sessions(settings)) as session:
        run = session.get(Run, run_id)
        assert run is not None
        run.request = {**run.request, "seed": 99}  # another run's settings
    verify = client.get(f"/runs/{run_id}/trace/verify").json()
    assert verify["ok"] is False
    assert verify["broken"]["table"] == "decisions" and verify["broken"]["task_index"] == 0


def test_no_key_means_no_signature_and_a_404_for_the_public_key(client: TestClient) -> None:
    run_id = _completed(client)
    assert client.get(f"/runs/{run_id}/trace/verify").json()["signature"] is None
    assert client.get("/audit/public-key").status_code == 404


def test_a_sign_off_is_signed_too(settings: Settings, tmp_path: Path) -> None:
    signed = _signed_settings(settings, tmp_path)
    with TestClient(create_app(signed)) as client:
        run_id = _completed(client)
        answer = client.post(f"/runs/{run_id}/signoff", json={"statement": "checked on site"})
        assert answer.status_code == 201, answer.text
        verify = client.get(f"/runs/{run_id}/trace/verify").json()
        export = _export(client, run_id, tmp_path / "signed-off.jsonl")
        pem = _public_key_file(client, tmp_path / "public.pem")
    assert verify["ok"] is True
    assert verify["signature"]["reason"] == "signoff" and verify["signature"]["valid"] is True
    header = json.loads(export.read_text().splitlines()[0])
    assert [s["reason"] for s in header["signatures"]] == ["completed", "signoff"]
    assert check_offline(export, pem).returncode == 0


def test_a_revision_whose_last_task_is_pinned_is_signed_and_signed_off_at_its_real_heads(
    settings: Settings, tmp_path: Path
) -> None:
    # A revision's decision chain runs through its pins first: when the queue's last task
    # is pinned, the head is the last decision the revision made, not the last task index.
    signed = _signed_settings(settings, tmp_path)
    change = {"type": "robot_unavailable", "robot": "heavy"}
    with TestClient(create_app(signed)) as client:
        parent = _completed(client)
        body = {"changes": [change], "pin": {"task_ids": [102]}, "reason": "last task kept"}
        revision = client.post(f"/runs/{parent}/revisions", json=body).json()["id"]
        eventually(
            lambda: client.get(f"/runs/{revision}").json()["status"],
            until=lambda status: status == "completed",
            what="the revision completed",
        )
        completed = client.get(f"/runs/{revision}/trace/verify").json()
        answer = client.post(f"/runs/{revision}/signoff", json={"statement": "checked"})
        assert answer.status_code == 201, answer.text
        verify = client.get(f"/runs/{revision}/trace/verify").json()
        # A revision of it starts from those heads too.
        again = client.post(
            f"/runs/{revision}/revisions",
            json={"changes": [{"type": "robot_available", "robot": "heavy"}], "reason": "back"},
        ).json()["id"]
        eventually(
            lambda: client.get(f"/runs/{again}").json()["status"],
            until=lambda status: status == "completed",
            what="the second revision completed",
        )
        link = client.get(f"/runs/{again}/trace/verify").json()["parent"]
        export = _export(client, revision, tmp_path / "revision.jsonl")
        pem = _public_key_file(client, tmp_path / "public.pem")
    assert completed["signature"]["valid"] is True, completed["signature"]
    assert answer.json()["heads"] == completed["heads"]
    assert verify["ok"] is True and verify["signoffs_ok"] is True
    assert verify["signature"]["reason"] == "signoff" and verify["signature"]["valid"] is True
    assert link["ok"] is True, link
    checked = check_offline(export, pem)
    assert checked.returncode == 0, checked.stdout + checked.stderr
