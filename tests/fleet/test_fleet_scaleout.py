"""One active fleet bridge per database (docs/fleet.md#one-bridge-per-database), end to end: two
real server processes on one PostgreSQL database, a mosquitto of the test's own (its log read
for client ids taken over), three simulated VDA 5050 robots, a 36-task durable run.

The holder is SIGKILLed after a dozen tasks and the standby takes over within the lease; the
killed process comes back as the standby, and the new holder is stopped gracefully (SIGTERM)
after two dozen, so the first takes over again at once. With the default client ids (both
processes on one host) and with one client id per process:

- every task is done or failed by the robots;
- every (orderId, orderUpdateId) crosses the broker once (counted by a subscriber);
- the broker never closed a client for another under its id ("already connected");
- each task's outcome is reported once and learned once (the site's outcome rows).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from benchmarks.mosquitto import broker
from tests.fleet.test_fleet_e2e import Simulator, online
from tests.support.mqtt_broker import Recorder
from tests.support.polling import eventually
from tests.support.postgres import fresh_database, query
from tests.support.server import Server

pytestmark = pytest.mark.e2e

ROBOTS = ("robot-1", "robot-2", "robot-3")
TASKS = 36
LEASE_S = 3.0
POLL_S = 0.5
# What a takeover may take beyond the lease, on two loaded cores: the standby's next look,
# its own transaction, and this test's poll of /health.
SLACK_S = 2.5
TAKEN_OVER = "already connected"


@pytest.fixture
def own_broker(tmp_path: Path) -> Iterator[tuple[str, Path]]:
    """A mosquitto of this test's own, and the file it logs to."""
    log = tmp_path / "mosquitto.log"
    with broker(log_to=log) as url:
        yield url, log


@pytest.fixture
def database() -> Iterator[str]:
    with fresh_database("ltaa_fleet") as url:
        yield url


def body() -> dict[str, Any]:
    features = [["heavy"], ["careful"], ["dexterous"], ["heavy", "careful"]]
    skills = [
        {"heavy": 0.95, "careful": 0.4, "dexterous": 0.3},
        {"heavy": 0.5, "careful": 0.9, "dexterous": 0.7},
        {"heavy": 0.3, "careful": 0.6, "dexterous": 0.95},
    ]
    return {
        "tasks": [
            {"id": f"T{i}", "name": f"task {i}", "features": features[i % 4]} for i in range(TASKS)
        ],
        "robots": [{"name": r, "success": skills[i]} for i, r in enumerate(ROBOTS)],
        "reasoner": "rules",
    }


def bridge(server: Server) -> dict[str, Any]:
    state: dict[str, Any] = httpx.get(f"{server.url}/health", timeout=5).json()["fleet_bridge"]
    return state


def becomes_active(server: Server, timeout: float) -> float:
    """Seconds until the server says it is the active bridge."""
    began = time.monotonic()
    eventually(
        lambda: bridge(server)["active"],
        timeout=timeout,
        interval=0.05,
        what=f"the server on {server.port} the active bridge",
        context=lambda: server.logged()[-3000:],
    )
    return time.monotonic() - began


def finals(server: Server, run_id: str) -> int:
    state = httpx.get(f"{server.url}/runs/{run_id}", params={"limit": 1000}).json()
    if state.get("superseded_by"):
        return finals(server, state["superseded_by"])
    return sum(
        (a.get("execution") or {}).get("state") in ("done", "failed") for a in state["assignments"]
    )


def reaches(server: Server, run_id: str, n: int, timeout: float = 120) -> None:
    eventually(
        lambda: finals(server, run_id),
        until=lambda done: done >= n,
        timeout=timeout,
        interval=0.1,
        what=f"{n} tasks of {run_id} done or failed by the robots",
    )


@pytest.mark.parametrize("ids", ["defaults", "one per process"])
def test_the_holder_killed_then_stopped_sends_each_order_once(
    tmp_path: Path, database: str, own_broker: tuple[str, Path], interface: str, ids: str
) -> None:
    mqtt_url, broker_log = own_broker
    env = {
        "LTAA_DATABASE_URL": database,
        "LTAA_MQTT_URL": mqtt_url,
        "LTAA_MQTT_INTERFACE": interface,
        "LTAA_MQTT_LEASE_S": str(LEASE_S),
        "LTAA_LEASE_S": str(LEASE_S),
        "LTAA_CLAIM_POLL_S": str(POLL_S),
    }

    def own(name: str) -> dict[str, str]:
        mine = {"LTAA_WORKER_NAME": name}
        if ids == "one per process":
            mine["LTAA_MQTT_CLIENT_ID"] = f"ltaa-{name}"
        return {**env, **mine}

    a = Server(tmp_path / "a", env=own("api-a"))
    b = Server(tmp_path / "b", env=own("api-b"))
    recorder = Recorder(mqtt_url, interface).start()
    sim = Simulator(
        mqtt_url,
        interface,
        tmp_path / "simulator.log",
        **{"--robots": str(len(ROBOTS)), "--default-duration-s": "0.1"},
    )
    try:
        a.start()
        becomes_active(a, timeout=30)
        b.start()
        assert bridge(b)["active"] is False
        assert bridge(b)["holder"] == bridge(a)["this_process"]
        page = httpx.get(f"{b.url}/console/fleet").text
        assert "stands by" in page and bridge(a)["this_process"] in page
        online(a, len(ROBOTS))
        run_id = httpx.post(f"{a.url}/runs", json=body()).json()["id"]
        reaches(b, run_id, 12)

        a.kill()
        killed_s = becomes_active(b, timeout=LEASE_S + POLL_S + SLACK_S + 30)
        assert killed_s <= LEASE_S + POLL_S + SLACK_S, f"took over in {killed_s:.1f} s"
        a.start()
        assert bridge(a)["active"] is False and bridge(a)["holder"] == bridge(b)["this_process"]
        reaches(a, run_id, 24)

        b.stop()  # SIGTERM: the lease is released at once
        stopped_s = becomes_active(a, timeout=LEASE_S + SLACK_S + 30)
        assert stopped_s < LEASE_S, f"took over after a graceful stop in {stopped_s:.1f} s"
        reaches(a, run_id, TASKS)
        print(f"[{ids}] taken over {killed_s:.2f} s after SIGKILL, {stopped_s:.2f} s after SIGTERM")

        assert recorder.invalid == []
        published = recorder.orders_published()
        twice = {k: v for k, v in published.items() if v > 1}
        assert twice == {}, f"orders published twice: {twice}"
        assert len({order for order, _ in published}) == TASKS
        taken = [line for line in broker_log.read_text().splitlines() if TAKEN_OVER in line]
        assert taken == []
        outcomes = query(
            database,
            "SELECT count(*), count(DISTINCT (run_id, task_index)) FROM site_reports",
        )
        assert outcomes[0] == (TASKS, TASKS)
        reported = Counter(
            (update["task_id"], update["state"])
            for (detail,) in query(
                database,
                "SELECT detail FROM run_events WHERE kind = 'execution_reported' "
                "UNION ALL SELECT detail FROM run_annotations WHERE kind = 'execution_reported'",
            )
            for update in detail["updates"]  # type: ignore[index]
        )
        assert len(reported) >= TASKS and max(reported.values()) == 1
        # Each process said when it became the active bridge: a twice, b once.
        assert a.log.read_text().count("is the active bridge") == 2
        assert b.log.read_text().count("is the active bridge") == 1
    finally:
        sim.stop()
        recorder.stop()
        a.stop()
        b.stop()
