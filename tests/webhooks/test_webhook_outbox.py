"""The outbox writer, called directly on a real SQLite file: which events make which
deliveries, for whom, in the caller's transaction."""

from __future__ import annotations

import json
from datetime import timedelta
from pathlib import Path

import pytest
from sqlalchemy.orm import Session, sessionmaker

from app.store.db import make_engine, make_session_factory, transaction
from app.store.migrate import upgrade_head
from app.store.models import utcnow
from app.store.webhook_models import WebhookDelivery, WebhookSubscription
from app.webhooks.events import TYPE_OF_KIND, WebhookEventType
from app.webhooks.outbox import enqueue_for_event
from tests.support.factories import decision_row, run_row

RUN_ID = "a" * 32


@pytest.fixture
def sessions(tmp_path: Path) -> sessionmaker[Session]:
    url = f"sqlite:///{tmp_path / 'app.db'}"
    upgrade_head(url)
    return make_session_factory(make_engine(url))


def add_subscription(
    sessions: sessionmaker[Session], sub_id: str, events: list[str], ago_s: float = 1.0
) -> None:
    with transaction(sessions) as session:
        session.add(
            WebhookSubscription(
                id=sub_id,
                url="https://hooks.example/x",
                events=events,
                description="",
                created_at=utcnow() - timedelta(seconds=ago_s),
                dedupe_key=sub_id,
            )
        )


def stored(sessions: sessionmaker[Session]) -> list[WebhookDelivery]:
    with sessions() as session:
        return list(session.query(WebhookDelivery).order_by(WebhookDelivery.subscription_id))


def test_every_spec_type_exists_and_kinds_map_as_documented() -> None:
    assert {t.value for t in WebhookEventType} == {
        "run.created",
        "run.completed",
        "run.failed",
        "run.cancelled",
        "run.interrupted",
        "run.superseded",
        "run.revised",
        "review.requested",
        "review.resolved",
        "run.signed_off",
        "budget.exhausted",
        "llm.gave_up",
    }
    assert TYPE_OF_KIND["llm_gave_up"] is WebhookEventType.LLM_GAVE_UP
    assert TYPE_OF_KIND["integrity_failed"] is WebhookEventType.RUN_FAILED
    assert TYPE_OF_KIND["budget_exhausted"] is WebhookEventType.BUDGET_EXHAUSTED
    assert TYPE_OF_KIND["review_requested"] is WebhookEventType.REVIEW_REQUESTED
    assert TYPE_OF_KIND["review_resolved"] is WebhookEventType.REVIEW_RESOLVED
    assert "started" not in TYPE_OF_KIND and "resumed" not in TYPE_OF_KIND


def test_one_delivery_per_matching_live_subscription(sessions: sessionmaker[Session]) -> None:
    add_subscription(sessions, "all", ["*"])
    add_subscription(sessions, "failures", ["run.failed"])
    add_subscription(sessions, "done", ["run.completed"])
    add_subscription(sessions, "gone", ["*"])
    with transaction(sessions) as session:
        session.get(WebhookSubscription, "gone").deleted_at = utcnow()  # type: ignore[union-attr]
    with transaction(sessions) as session:
        made = enqueue_for_event(session, run_id=RUN_ID, kind="failed", detail={"e": 1}, seq=7)
    assert sorted(d.subscription_id for d in made) == ["all", "failures"]
    rows = stored(sessions)
    assert [(d.subscription_id, d.event_type, d.event_seq, d.state) for d in rows] == [
        ("all", "run.failed", 7, "pending"),
        ("failures", "run.failed", 7, "pending"),
    ]
    assert len({d.id for d in rows}) == 2 and all(d.id.startswith("msg_") for d in rows)
    body = json.loads(rows[0].payload)
    assert body["type"] == "run.failed" and body["timestamp"].endswith("Z")
    assert body["data"] == {
        "e": 1,
        "run_id": RUN_ID,
        "event": "failed",
        "seq": 7,
        "status": "failed",
    }


def test_subscriptions_created_after_the_event_get_nothing(
    sessions: sessionmaker[Session],
) -> None:
    add_subscription(sessions, "later", ["*"], ago_s=-60)  # created "after" the event
    with transaction(sessions) as session:
        assert enqueue_for_event(session, run_id=RUN_ID, kind="created", detail={}, seq=1) == []
    assert stored(sessions) == []


def test_deliveries_roll_back_with_the_event_transaction(
    sessions: sessionmaker[Session],
) -> None:
    add_subscription(sessions, "all", ["*"])
    with pytest.raises(RuntimeError), transaction(sessions) as session:
        enqueue_for_event(session, run_id=RUN_ID, kind="created", detail={}, seq=1)
        session.flush()
        raise RuntimeError("the event's transaction fails")
    assert stored(sessions) == []


def test_completed_carries_status_and_the_runs_expected_success(
    sessions: sessionmaker[Session],
) -> None:
    add_subscription(sessions, "all", ["*"])
    with transaction(sessions) as session:
        session.add(run_row(RUN_ID, "completed", n_tasks=2))
        session.flush()
        for index, success in enumerate((0.8, 0.6)):
            session.add(decision_row(RUN_ID, index, expected_success=success))
        session.flush()
        enqueue_for_event(session, run_id=RUN_ID, kind="completed", detail={"decisions": 2}, seq=3)
    data = json.loads(stored(sessions)[0].payload)["data"]
    assert data["status"] == "completed" and data["decisions"] == 2
    assert data["expected_success"] == pytest.approx(0.7)


def test_server_key_rotation_reencrypts_every_secret(
    sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    from cryptography.fernet import Fernet

    from app.store.webhook_models import WebhookSecret
    from app.webhooks.errors import SecretKeyError
    from app.webhooks.secret_box import SecretBox, new_secret
    from app.webhooks.service import reencrypt_secrets

    old_key, new_key = Fernet.generate_key().decode(), Fernet.generate_key().decode()
    old = SecretBox.from_setting(old_key, tmp_path)
    add_subscription(sessions, "all", ["*"])
    secret = new_secret()
    with transaction(sessions) as session:
        session.add(WebhookSecret(subscription_id="all", ciphertext=old.encrypt(secret)))
    both = SecretBox.from_setting(f"{new_key},{old_key}", tmp_path)
    assert reencrypt_secrets(sessions=sessions, box=both) == 1
    only_new = SecretBox.from_setting(new_key, tmp_path)
    with sessions() as session:
        (ciphertext,) = [row.ciphertext for row in session.query(WebhookSecret)]
    assert only_new.decrypt(ciphertext) == secret
    with pytest.raises(SecretKeyError, match="differs"):
        old.decrypt(ciphertext)
    with pytest.raises(SecretKeyError, match="entry 2 is not a Fernet key"):
        SecretBox.from_setting(f"{new_key},not-a-key", tmp_path)
