"""GET /runs/{id}/events in-process: order, Last-Event-ID, and bad requests."""

from __future__ import annotations

from datetime import datetime, timedelta
from itertools import pairwise

from fastapi.testclient import TestClient

from tests.support.sse import Event, parse_events

BASELINE = {"scenario": "baseline", "mode": "balanced"}


def stream(client: TestClient, path: str, **headers: str) -> list[Event]:
    with client.stream("GET", path, headers=headers) as response:
        assert response.status_code == 200
        assert response.headers["content-type"].startswith("text/event-stream")
        return list(parse_events(response.iter_lines()))


def test_a_watched_run_streams_every_event_in_order_then_ends(client: TestClient) -> None:
    run_id = client.post("/runs", json=BASELINE).json()["id"]
    everything = stream(client, f"/runs/{run_id}/events")  # connected while it runs
    # The status, on connecting and at each change, the stream's last word when finished.
    statuses = [e.data for e in everything if e.event == "status"]
    assert statuses[-1] == {"status": "completed", "finished": True}
    assert everything[-1].event == "status" and everything[-1].id == "3-36"
    assert all(not s["finished"] for s in statuses[:-1])
    assert all(a["status"] != b["status"] for a, b in pairwise(statuses))
    events = [e for e in everything if e.event != "status"]

    kinds = [e.data["kind"] if e.event == "run" else e.event for e in events]
    assert kinds == ["created", "started", *["decision"] * 36, "completed"]
    decisions = [e.data for e in events if e.event == "decision"]
    assert [d["task_index"] for d in decisions] == list(range(36))
    assert set(decisions[0]) >= {
        "task_index",
        "task_id",
        "task_name",
        "robot",
        "phase",
        "quality",
        "fallback",
        "regret",
        "expected_success",
    }
    assert decisions[0]["phase"] == "early" and decisions[-1]["phase"] == "late"
    assert everything[0].retry == 1000 and events[0].id == "1-0" and events[-1].id == "3-36"
    # The stream agrees with the run's own record.
    assignments = client.get(f"/runs/{run_id}").json()["assignments"]
    assert [d["robot"] for d in decisions] == [a["robot"] for a in assignments]
    # Task ids as the request gave them (numbers here), as GET /runs/{id} shows them.
    assert [d["task_id"] for d in decisions] == [a["task_id"] for a in assignments]
    assert all(isinstance(d["task_id"], int) for d in decisions)
    # Times as RFC 3339 with their offset, as in every other response.
    for event in (e for e in events if e.event == "run"):
        assert datetime.fromisoformat(event.data["at"]).utcoffset() == timedelta(0)
        assert event.data["at"][10] == "T"  # not str()'s "2026-11-23 02:28:33+00:00"


def test_last_event_id_continues_where_the_stream_stopped(client: TestClient) -> None:
    run_id = client.post("/runs", json=BASELINE).json()["id"]
    full = stream(client, f"/runs/{run_id}/events")
    cut = next(
        i for i, e in enumerate(full) if e.event == "decision" and e.data["task_index"] == 29
    )
    rest = stream(client, f"/runs/{run_id}/events", **{"Last-Event-ID": str(full[cut].id)})
    assert [(e.event, e.id, e.data) for e in rest] == [
        (e.event, e.id, e.data) for e in full[cut + 1 :]
    ]
    assert [e.data.get("task_index") for e in rest][:6] == list(range(30, 36))
    # After the last event only the (finished) status is left to say.
    last = stream(client, f"/runs/{run_id}/events", **{"Last-Event-ID": str(full[-1].id)})
    assert [(e.event, e.data) for e in last] == [
        ("status", {"status": "completed", "finished": True})
    ]


def test_unknown_run_and_bad_last_event_id_are_4xx_in_the_error_shape(
    client: TestClient,
) -> None:
    missing = client.get(f"/runs/{'0' * 32}/events")
    assert missing.status_code == 404
    assert missing.json()["detail"][0]["loc"] == ["path", "run_id"]
    run_id = client.post("/runs", json=BASELINE).json()["id"]
    bad = client.get(f"/runs/{run_id}/events", headers={"Last-Event-ID": "yesterday"})
    assert bad.status_code == 422
    assert bad.json()["detail"] == [
        {
            "loc": ["header", "last-event-id"],
            "type": "value_error",
            "msg": "expected an event id sent by this stream, like '3-17'",
        }
    ]
