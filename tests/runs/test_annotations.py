"""The annotation chain: records made about a run after it finished, append-only and
hash-chained, checked by trace/verify beside (never inside) the decision and event chains."""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.domain.annotations import AnnotationKind
from app.runs import lifecycle
from app.store import chain
from app.store.db import make_engine, make_session_factory, transaction
from app.store.models import RunAnnotation
from tests.support.polling import wait_until

BASELINE = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}


def _completed_run(client: TestClient) -> str:
    run_id = str(client.post("/runs", json=BASELINE).json()["id"])
    assert wait_until(client, run_id)["status"] == "completed"
    return run_id


@pytest.fixture
def sessions(settings: Settings) -> Iterator[sessionmaker[Session]]:
    engine = make_engine(settings.db_url)
    yield make_session_factory(engine)
    engine.dispose()


def _verify(client: TestClient, run_id: str) -> dict[str, Any]:
    response = client.get(f"/runs/{run_id}/trace/verify")
    assert response.status_code == 200, response.text
    return dict(response.json())


def test_annotations_chain_apart_from_the_decisions_and_events(
    client: TestClient, sessions: sessionmaker[Session], settings: Settings
) -> None:
    run_id = _completed_run(client)
    before = _verify(client, run_id)
    with transaction(sessions) as session:
        first = lifecycle.record_annotation(
            session, run_id=run_id, kind=AnnotationKind.SIGNOFF, detail={"note": "one"}
        )
        second = lifecycle.record_annotation(
            session, run_id=run_id, kind=AnnotationKind.SIGNOFF, detail={"note": "two"}
        )
    assert (first.seq, second.seq) == (1, 2)
    assert first.chain_hash == chain.annotation_link(
        chain.genesis("annotations", run_id),
        {"seq": 1, "kind": "signoff", "detail": {"note": "one"}},
    )
    after = _verify(client, run_id)
    assert after["ok"] is True and after["annotations"] == 2
    assert after["annotations_head"] == second.chain_hash
    # The decision and event chains (what a sign-off signs) are exactly as before.
    for key in ("decisions", "events"):
        assert after[key] == before[key]
        assert after["heads"][key] == before["heads"][key]

    conn = sqlite3.connect(settings.data_dir / "ltaa.db", isolation_level=None)
    try:
        conn.execute(
            "UPDATE run_annotations SET detail = json_set(detail, '$.note', 'x') WHERE seq = 1"
        )
    finally:
        conn.close()
    broken = _verify(client, run_id)
    assert broken["ok"] is False
    assert broken["broken"]["table"] == "annotations" and broken["broken"]["seq"] == 1
    assert broken["heads"]["decisions"] == before["heads"]["decisions"]


def test_an_annotation_from_another_run_never_verifies() -> None:
    detail = {"seq": 1, "kind": "signoff", "detail": {}}
    assert chain.annotation_link(
        chain.genesis("annotations", "a"), detail
    ) != chain.annotation_link(chain.genesis("annotations", "b"), detail)
    # Nor passes for an event with the same content.
    assert chain.annotation_link("p", detail) != chain.event_link("p", detail)


def test_every_annotation_column_an_auditor_reads_is_in_the_chain() -> None:
    columns = {c.name for c in RunAnnotation.__table__.columns}
    assert set(chain.ANNOTATION_FIELDS) == columns - {
        "id",
        "run_id",
        "created_at",
        "chain_hash",
        "idempotency_key",  # how the request was retried, not what it recorded
        "request_digest",
    }
