"""Webhook subscriptions over the API, with the dispatcher delivering to a real receiver
on loopback (in-process app, real SQLite file, real HTTP)."""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from standardwebhooks import Webhook

from app.store.db import transaction
from app.webhooks.outbox import enqueue_for_event
from tests.fakes.webhook_receiver import Receiver, running_receiver
from tests.support.clients import ClientFactory
from tests.support.polling import eventually, wait_until

FAST = {"webhook_poll_s": 0.05, "webhook_retry_delays_s": [0.05, 0.05, 0.05, 0.05]}
RUN = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}


@pytest.fixture
def receiver() -> Iterator[Receiver]:
    with running_receiver() as r:
        yield r


@pytest.fixture
def lan(make_client: ClientFactory) -> TestClient:
    """Private targets allowed (the loopback receiver), a short retry schedule."""
    return make_client(webhook_allow_private=True, **FAST)


def subscribe(client: TestClient, url: str, events: list[str] | None = None, **headers: str) -> Any:
    response = client.post(
        "/webhooks", json={"url": url, "events": events or ["*"]}, headers=headers
    )
    assert response.status_code == 201, response.text
    return response.json()


def deliveries(client: TestClient, webhook_id: str) -> list[dict[str, Any]]:
    response = client.get(f"/webhooks/{webhook_id}/deliveries")
    assert response.status_code == 200, response.text
    return list(response.json())


def wait_deliveries(
    client: TestClient, webhook_id: str, done: Any, what: str = "the awaited state"
) -> list[dict[str, Any]]:
    return eventually(
        lambda: deliveries(client, webhook_id),
        until=lambda got: bool(got) and done(got),
        what=f"webhook {webhook_id}'s deliveries reached {what}",
        timeout=30,
        interval=0.05,
    )


def stored_deliveries(client: TestClient) -> list[Any]:
    from app.store.webhook_models import WebhookDelivery

    with client.app.state.webhooks.sessions() as session:  # type: ignore[attr-defined]
        return list(session.query(WebhookDelivery))


def one_error(response: Any, status: int) -> dict[str, Any]:
    assert response.status_code == status, response.text
    detail = response.json()["detail"]
    assert len(detail) >= 1
    return dict(detail[0])


# -- subscriptions ---------------------------------------------------------------------


def test_create_list_get_delete(lan: TestClient, receiver: Receiver) -> None:
    created = subscribe(lan, receiver.url, ["run.completed", "run.failed", "run.completed"])
    assert created["id"].startswith("wh_") and created["secret"].startswith("whsec_")
    assert created["events"] == ["run.completed", "run.failed"]  # sorted, deduplicated
    listed = lan.get("/webhooks").json()
    assert [w["id"] for w in listed] == [created["id"]]
    assert "secret" not in listed[0]  # shown once, at creation
    assert "secret" not in lan.get(f"/webhooks/{created['id']}").json()
    assert lan.delete(f"/webhooks/{created['id']}").status_code == 204
    assert lan.get("/webhooks").json() == []
    assert one_error(lan.get(f"/webhooks/{created['id']}"), 404)["loc"] == ["path", "webhook_id"]
    # Deleted, the same URL and events may be subscribed again.
    subscribe(lan, receiver.url, ["run.completed", "run.failed"])


@pytest.mark.parametrize(
    ("body", "loc", "words"),
    [
        ({"url": "https://x.example/h", "events": ["run.exploded"]}, ["body", "events", 0], "run."),
        ({"url": "https://x.example/h", "events": []}, ["body", "events"], "at least 1"),
        ({"url": "not a url", "events": ["*"]}, ["body", "url"], "whitespace"),
        ({"url": "/relative/path", "events": ["*"]}, ["body", "url"], "absolute"),
        ({"url": "http://", "events": ["*"]}, ["body", "url"], "absolute"),
        ({"url": "http://x.example:99999/h", "events": ["*"]}, ["body", "url"], "not a valid URL"),
        ({"url": "ftp://x.example/h", "events": ["*"]}, ["body", "url"], "scheme 'ftp'"),
        ({"url": "file:///etc/passwd", "events": ["*"]}, ["body", "url"], "absolute"),
        ({"url": "https://u:p@x.example/h", "events": ["*"]}, ["body", "url"], "credentials"),
        ({"url": "https://x.example/h", "events": ["*"], "secret": "x"}, ["body", "secret"], ""),
        ({"events": ["*"]}, ["body", "url"], "required"),
    ],
)
def test_bad_input_is_422_naming_the_field(
    client: TestClient, body: dict[str, Any], loc: list[Any], words: str
) -> None:
    err = one_error(client.post("/webhooks", json=body), 422)
    assert err["loc"] == loc and words in err["msg"], err


@pytest.mark.parametrize(
    "url",
    [
        "http://169.254.169.254/latest/meta-data/",
        "http://10.0.0.1/",
        "http://127.0.0.1:9/hooks",
        "http://[::1]/hooks",
        "http://[::ffff:10.0.0.1]/hooks",
        "http://localhost:8000/hooks",
        "http://192.168.1.20/hooks",
        "http://0.0.0.0/hooks",
    ],
)
def test_private_targets_are_refused_without_the_setting(client: TestClient, url: str) -> None:
    err = one_error(client.post("/webhooks", json={"url": url, "events": ["*"]}), 422)
    assert err["loc"] == ["body", "url"] and err["type"] == "private_address"
    assert "LTAA_WEBHOOK_ALLOW_PRIVATE" in err["msg"]


def test_duplicate_subscription_is_409_naming_the_url(lan: TestClient, receiver: Receiver) -> None:
    first = subscribe(lan, receiver.url, ["run.failed", "run.completed"])
    err = one_error(
        lan.post(
            "/webhooks", json={"url": receiver.url, "events": ["run.completed", "run.failed"]}
        ),
        409,
    )
    assert err["loc"] == ["body", "url"] and first["id"] in err["msg"]
    # Other events to the same URL are another subscription.
    subscribe(lan, receiver.url, ["run.created"])


def test_idempotency_key_replays_the_first_answer(lan: TestClient, receiver: Receiver) -> None:
    first = subscribe(lan, receiver.url, ["*"], **{"Idempotency-Key": "k-1"})
    again = lan.post(
        "/webhooks", json={"events": ["*"], "url": receiver.url}, headers={"Idempotency-Key": "k-1"}
    )
    assert again.status_code == 201 and again.headers["idempotent-replayed"] == "true"
    assert again.json() == first  # the secret too: a lost first answer loses nothing
    assert len(lan.get("/webhooks").json()) == 1
    other = lan.post(
        "/webhooks",
        json={"events": ["run.failed"], "url": receiver.url},
        headers={"Idempotency-Key": "k-1"},
    )
    err = one_error(other, 409)
    assert err["loc"] == ["header", "Idempotency-Key"] and first["id"] in err["msg"]
    twice = lan.post(
        "/webhooks",
        json={"events": ["run.failed"], "url": receiver.url},
        headers=[("Idempotency-Key", "a"), ("Idempotency-Key", "b")],
    )
    assert one_error(twice, 422)["type"] == "duplicate_header"
    # As every route documents the key: visible ASCII, spaces only between characters.
    for bad in (b"k\t1", "clé".encode()):  # as raw bytes: httpx sends only ASCII str
        refused = lan.post(
            "/webhooks",
            json={"events": ["run.failed"], "url": receiver.url},
            headers=[(b"Idempotency-Key", bad)],
        )
        err = one_error(refused, 422)
        assert err["loc"] == ["header", "Idempotency-Key"] and err["type"] == "invalid_header"
    assert len(lan.get("/webhooks").json()) == 1


def test_the_database_holds_no_secret_in_plain_text(
    lan: TestClient, receiver: Receiver, settings: Any
) -> None:
    created = subscribe(lan, receiver.url)
    rotated = lan.post(f"/webhooks/{created['id']}/rotate-secret").json()
    db = Path(settings.data_dir) / "ltaa.db"
    raw = db.read_bytes() + Path(f"{db}-wal").read_bytes()
    for secret in (created["secret"], rotated["secret"]):
        assert secret.encode() not in raw
        assert secret.removeprefix("whsec_").encode() not in raw
    with sqlite3.connect(db) as conn:
        rows = conn.execute("SELECT ciphertext FROM webhook_secrets").fetchall()
    assert len(rows) == 2 and all(r[0].startswith("gAAAA") for r in rows)  # Fernet tokens
    key_file = Path(settings.data_dir) / "webhook-secret.key"
    assert key_file.stat().st_mode & 0o777 == 0o600


# -- delivery --------------------------------------------------------------------------


def enqueue(client: TestClient, run_id: str, kind: str = "created", seq: int = 1) -> None:
    with transaction(client.app.state.webhooks.sessions) as session:  # type: ignore[attr-defined]
        enqueue_for_event(session, run_id=run_id, kind=kind, detail={"note": "test"}, seq=seq)


def test_a_run_sends_created_and_completed_signed(lan: TestClient, receiver: Receiver) -> None:
    hook = subscribe(lan, receiver.url)
    run_id = lan.post("/runs", json=RUN).json()["id"]
    state = wait_until(lan, run_id)
    assert state["status"] == "completed"
    receiver.wait_for(lambda got: len(got) >= 2, what="two requests")
    bodies = receiver.verified(hook["secret"])  # raises unless every signature verifies
    by_type = {b["type"]: b for b in bodies}
    assert set(by_type) == {"run.created", "run.completed"}
    done = by_type["run.completed"]["data"]
    assert done["run_id"] == run_id and done["status"] == "completed"
    assert done["expected_success"] == pytest.approx(state["metrics"]["expected_success"])
    assert by_type["run.created"]["data"]["run_id"] == run_id
    assert by_type["run.completed"]["timestamp"].endswith("Z")


def test_a_sign_off_sends_run_signed_off(lan: TestClient, receiver: Receiver) -> None:
    # Subscribed to everything from the start: the sign-off (annotation 1) must not collide
    # with the run's event 1 (`created`) in the outbox.
    hook = subscribe(lan, receiver.url, ["*"])
    run_id = lan.post("/runs", json=RUN).json()["id"]
    assert wait_until(lan, run_id)["status"] == "completed"
    receiver.wait_for(lambda got: len(got) >= 2, what="run.created and run.completed")
    signed = lan.post(f"/runs/{run_id}/signoff", json={"statement": "checked on site"})
    assert signed.status_code == 201, signed.text
    receiver.wait_for(lambda got: len(got) >= 3, what="the sign-off webhook")
    (body,) = [b for b in receiver.verified(hook["secret"]) if b["type"] == "run.signed_off"]
    assert body["type"] == "run.signed_off"
    data = body["data"]
    assert data["run_id"] == run_id and data["statement"] == "checked on site"
    assert data["heads"] == signed.json()["heads"]


def test_three_500s_then_delivered_on_the_fourth_with_one_id(
    lan: TestClient, receiver: Receiver
) -> None:
    hook = subscribe(lan, receiver.url, ["run.created"])
    receiver.script = [500, 500, 500]
    enqueue(lan, "r" * 32)
    receiver.wait_for(lambda got: len(got) == 4, what="four attempts")
    got = receiver.snapshot()
    assert len({r.headers["webhook-id"] for r in got}) == 1
    # Each attempt signed afresh: its own timestamp, each signature valid for it.
    wh = Webhook(hook["secret"])
    for r in got:
        wh.verify(r.body, r.headers)
    (delivery,) = wait_deliveries(lan, hook["id"], lambda d: d[0]["status"] == "delivered")
    assert delivery["id"] == got[0].headers["webhook-id"] and delivery["attempts"] == 4
    log = delivery["attempt_log"]
    assert [a["status_code"] for a in log] == [500, 500, 500, 204]
    assert [a["outcome"] for a in log] == ["http_error"] * 3 + ["delivered"]
    assert all(a["latency_ms"] > 0 for a in log)


def test_failed_after_the_schedule_then_a_manual_retry_delivers(
    lan: TestClient, receiver: Receiver
) -> None:
    hook = subscribe(lan, receiver.url, ["run.created"])
    receiver.script = [503] * 5  # 1 attempt + 4 retries, all refused
    enqueue(lan, "r" * 32)
    (failed,) = wait_deliveries(lan, hook["id"], lambda d: d[0]["status"] == "failed")
    assert failed["attempts"] == 5 and failed["last_status_code"] == 503
    retried = lan.post(f"/webhooks/{hook['id']}/deliveries/{failed['id']}/retry")
    assert retried.status_code == 202 and retried.json()["status"] == "pending"
    (done,) = wait_deliveries(lan, hook["id"], lambda d: d[0]["status"] == "delivered")
    assert done["attempts"] == 6 and len(receiver.ids()) == 1
    missing = lan.post(f"/webhooks/{hook['id']}/deliveries/msg_nope/retry")
    assert one_error(missing, 404)["loc"] == ["path", "delivery_id"]


def test_redirects_are_not_followed(lan: TestClient, receiver: Receiver) -> None:
    hook = subscribe(lan, receiver.url, ["run.created"])
    receiver.script = [302]
    enqueue(lan, "r" * 32)
    (d,) = wait_deliveries(lan, hook["id"], lambda d: d[0]["attempts"] >= 2)
    assert d["attempt_log"][0]["outcome"] == "http_error"
    assert "not followed" in d["attempt_log"][0]["error"]


def test_a_name_resolving_to_a_private_address_is_refused_at_delivery(
    make_client: ClientFactory, receiver: Receiver
) -> None:
    # The name passes at creation (it is not an address); at delivery it resolves, through
    # the resolver seam, to the loopback receiver: refused, and the log says why.
    client = make_client(
        test_webhook_resolve="hooks.site.example=127.0.0.1,meta.example=169.254.169.254",
        **FAST,
    )
    hook = subscribe(client, f"http://hooks.site.example:{receiver.port}/hooks", ["run.created"])
    enqueue(client, "r" * 32)
    (d,) = wait_deliveries(client, hook["id"], lambda d: d[0]["status"] == "failed")
    assert {a["outcome"] for a in d["attempt_log"]} == {"refused"}
    assert "127.0.0.1" in d["last_error"] and "not a global address" in d["last_error"]
    assert receiver.snapshot() == []  # nothing reached it


def test_with_the_setting_a_name_is_delivered_to_the_checked_address(
    make_client: ClientFactory, receiver: Receiver
) -> None:
    client = make_client(
        webhook_allow_private=True, test_webhook_resolve="hooks.site.example=127.0.0.1", **FAST
    )
    hook = subscribe(client, f"http://hooks.site.example:{receiver.port}/hooks", ["run.created"])
    enqueue(client, "r" * 32)
    receiver.wait_for(lambda got: len(got) == 1, what="one request")
    # Connected to the resolved address; the Host header still names the host.
    assert receiver.snapshot()[0].headers["host"] == f"hooks.site.example:{receiver.port}"
    receiver.verified(hook["secret"])


def test_rotation_signs_with_both_secrets_during_the_grace(
    lan: TestClient, receiver: Receiver
) -> None:
    hook = subscribe(lan, receiver.url, ["run.created"], **{"Idempotency-Key": "create-1"})
    rotated = lan.post(
        f"/webhooks/{hook['id']}/rotate-secret", headers={"Idempotency-Key": "rotate-1"}
    )
    assert rotated.status_code == 200 and rotated.json()["secret"] != hook["secret"]
    replay = lan.post(
        f"/webhooks/{hook['id']}/rotate-secret", headers={"Idempotency-Key": "rotate-1"}
    )
    assert replay.json()["secret"] == rotated.json()["secret"]
    assert replay.headers["idempotent-replayed"] == "true"
    enqueue(lan, "r" * 32)
    receiver.wait_for(lambda got: len(got) == 1, what="one request")
    (request,) = receiver.snapshot()
    assert len(request.headers["webhook-signature"].split(" ")) == 2
    Webhook(hook["secret"]).verify(request.body, request.headers)  # old: still valid
    Webhook(rotated.json()["secret"]).verify(request.body, request.headers)


def test_rotated_out_secret_stops_signing_after_the_grace(
    make_client: ClientFactory, receiver: Receiver
) -> None:
    client = make_client(webhook_allow_private=True, webhook_secret_grace_s=0, **FAST)
    hook = subscribe(client, receiver.url, ["run.created"])
    new = client.post(f"/webhooks/{hook['id']}/rotate-secret").json()["secret"]
    enqueue(client, "r" * 32)
    receiver.wait_for(lambda got: len(got) == 1, what="one request")
    (request,) = receiver.snapshot()
    assert len(request.headers["webhook-signature"].split(" ")) == 1
    Webhook(new).verify(request.body, request.headers)


def test_events_before_a_subscription_and_unsubscribed_types_send_nothing(
    lan: TestClient, receiver: Receiver
) -> None:
    enqueue(lan, "a" * 32, seq=1)  # before any subscription
    hook = subscribe(lan, receiver.url, ["run.failed"])
    enqueue(lan, "a" * 32, kind="created", seq=2)  # not subscribed
    enqueue(lan, "a" * 32, kind="started", seq=3)  # no webhook type
    enqueue(lan, "a" * 32, kind="integrity_failed", seq=4)
    # Only the subscribed event made a delivery at all: nothing else can arrive later.
    assert [d.event_type for d in stored_deliveries(lan)] == ["run.failed"]
    receiver.wait_for(lambda got: len(got) == 1, what="one request")
    (only,) = receiver.verified(hook["secret"])
    assert only["type"] == "run.failed" and only["data"]["status"] == "failed"


def test_delete_cancels_waiting_deliveries(make_client: ClientFactory, receiver: Receiver) -> None:
    client = make_client(webhook_allow_private=True, webhook_dispatch=False)
    hook = subscribe(client, receiver.url, ["run.created"])
    enqueue(client, "r" * 32)
    assert [d["status"] for d in deliveries(client, hook["id"])] == ["pending"]
    client.delete(f"/webhooks/{hook['id']}")
    assert [d.state for d in stored_deliveries(client)] == ["cancelled"]


def test_metrics_report_deliveries_attempts_queue_and_latency(
    lan: TestClient, receiver: Receiver
) -> None:
    hook = subscribe(lan, receiver.url, ["run.created"])
    receiver.script = [500]
    enqueue(lan, "r" * 32)
    wait_deliveries(lan, hook["id"], lambda d: d[0]["status"] == "delivered")
    text = lan.get("/metrics").text
    assert 'ltaa_webhook_deliveries{status="delivered"} 1.0' in text
    assert 'ltaa_webhook_attempts_total{outcome="http_error"} 1.0' in text
    assert 'ltaa_webhook_attempts_total{outcome="delivered"} 1.0' in text
    assert "ltaa_webhook_queue_depth 0.0" in text
    assert "ltaa_webhook_delivery_latency_seconds_count 2.0" in text


def test_an_endless_response_body_is_read_only_up_to_the_cap(
    make_client: ClientFactory, receiver: Receiver
) -> None:
    # The timeout is per read, so without the cap an endless body would hold the attempt
    # (and its dispatcher thread) forever.
    client = make_client(webhook_allow_private=True, webhook_max_response_bytes=100_000, **FAST)
    hook = subscribe(client, receiver.url, ["run.created"])
    receiver.endless_body = True
    enqueue(client, "r" * 32)
    (d,) = wait_deliveries(client, hook["id"], lambda d: d[0]["status"] == "delivered")
    assert d["attempt_log"][0]["response_excerpt"] == "x" * 512


def test_a_receiver_slower_than_the_timeout_is_a_failed_attempt(
    make_client: ClientFactory, receiver: Receiver
) -> None:
    client = make_client(webhook_allow_private=True, webhook_timeout_s=0.3, **FAST)
    hook = subscribe(client, receiver.url, ["run.created"])
    receiver.delay_s = 1.0
    enqueue(client, "r" * 32)
    (d,) = wait_deliveries(client, hook["id"], lambda d: len(d[0]["attempt_log"]) >= 1)
    first = d["attempt_log"][0]
    assert first["outcome"] == "network_error" and "ReadTimeout" in first["error"]
    assert first["latency_ms"] < 900


def test_a_dripping_answer_is_cut_off_at_the_timeout(
    make_client: ClientFactory, receiver: Receiver
) -> None:
    # Each read arrives well within the timeout, but the whole answer never ends.
    client = make_client(webhook_allow_private=True, webhook_timeout_s=0.5, **FAST)
    hook = subscribe(client, receiver.url, ["run.created"])
    receiver.endless_body, receiver.drip_s = True, 0.05
    enqueue(client, "r" * 32)
    (d,) = wait_deliveries(client, hook["id"], lambda d: len(d[0]["attempt_log"]) >= 1)
    first = d["attempt_log"][0]
    assert first["outcome"] == "network_error" and "longer than the timeout" in first["error"]
    assert 450 < first["latency_ms"] < 1500


def test_a_review_request_sends_review_requested(lan: TestClient, receiver: Receiver) -> None:
    hook = subscribe(lan, receiver.url, ["review.requested"])
    created = lan.post("/runs", json={**RUN, "review": {"on": ["every_decision"]}})
    assert created.status_code == 202, created.text
    run_id = created.json()["id"]
    receiver.wait_for(lambda got: len(got) >= 1, what="a review request")
    (first, *_) = receiver.verified(hook["secret"])
    assert first["type"] == "review.requested" and first["data"]["run_id"] == run_id
    assert first["data"]["event"] == "review_requested"
