"""The plan reaches the robots (docs/fleet.md), end to end: a real mosquitto, a real server with
the bridge on, the simulator as a process of its own, nothing reported by hand.

- a durable 120-task run on six simulated robots completes with every task reported done or
  failed by the robots, and the site's estimates count each report once;
- the server SIGKILLed mid-run and started again: no order crosses the broker twice, none is
  lost, the run completes;
- robot 3's socket broken: its will says CONNECTIONBROKEN and the plan is revised to the others.
Every message on the broker is checked against the VDA 5050 2.1.0 schemas.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from app.graph.pause import PausePoint
from tests.support.mqtt_broker import Recorder
from tests.support.polling import eventually
from tests.support.server import ROOT, Server

pytestmark = pytest.mark.e2e

ROBOTS = [f"robot-{i}" for i in range(1, 7)]
FEATURES = [["heavy"], ["careful"], ["dexterous"], ["heavy", "careful"]]


def body(n: int) -> dict[str, Any]:
    skills = [
        {"heavy": 0.95, "careful": 0.4, "dexterous": 0.3},
        {"heavy": 0.5, "careful": 0.9, "dexterous": 0.7},
        {"heavy": 0.3, "careful": 0.6, "dexterous": 0.95},
    ]
    return {
        "tasks": [
            {"id": f"T{i}", "name": f"task {i}", "features": FEATURES[i % 4]} for i in range(n)
        ],
        "robots": [{"name": r, "success": skills[i % 3]} for i, r in enumerate(ROBOTS)],
        "reasoner": "rules",
    }


class Simulator:
    """`ltaa fleet simulate` in a process of its own; commands go to its standard input."""

    def __init__(self, url: str, interface: str, log: Path, **options: str) -> None:
        args = {
            "--url": url,
            "--interface": interface,
            "--robots": str(len(ROBOTS)),
            "--default-duration-s": "0.05",
            "--state-interval-s": "0.5",
            "--fail-share": "0.2",
            "--seed": "7",
            **options,
        }
        self.log = log
        self.out = log.open("wb")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "app.cli", "fleet", "simulate"]
            + [x for pair in args.items() for x in pair],
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=self.out,
            stderr=subprocess.STDOUT,
        )

    def say(self, command: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(f"{command}\n".encode())
        self.proc.stdin.flush()

    def lines(self) -> str:
        return self.log.read_text()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.say("quit")
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.out.close()


@pytest.fixture
def fleet(tmp_path: Path, mqtt_url: str, interface: str) -> Iterator[tuple[Server, Simulator]]:
    server = Server(
        tmp_path / "data",
        env={
            "LTAA_MQTT_URL": mqtt_url,
            "LTAA_MQTT_INTERFACE": interface,
            "LTAA_MQTT_MANUFACTURER": "ltaa-sim",
        },
    )
    sim = Simulator(mqtt_url, interface, tmp_path / "simulator.log")
    try:
        yield server, sim
    finally:
        sim.stop()
        server.stop()


def online(server: Server, n: int = len(ROBOTS)) -> None:
    eventually(
        lambda: [
            r
            for r in httpx.get(f"{server.url}/fleet/robots").json()["robots"]
            if r["connection"] == "ONLINE"
        ],
        until=lambda rows: len(rows) >= n,
        what=f"{n} robots ONLINE on the bridge",
    )


def reported(server: Server, run_id: str) -> dict[str, str]:
    """The execution state of every task of the run's lineage head, by task id."""
    state = httpx.get(f"{server.url}/runs/{run_id}", params={"limit": 1000}).json()
    if state.get("superseded_by"):
        return reported(server, state["superseded_by"])
    return {
        str(a["task_id"]): (a.get("execution") or {}).get("state", "") for a in state["assignments"]
    }


def all_final(server: Server, run_id: str, n: int, timeout: float = 180) -> dict[str, str]:
    def context() -> str:
        head = httpx.get(f"{server.url}/runs/{run_id}").json().get("superseded_by") or run_id
        state = httpx.get(f"{server.url}/runs/{head}", params={"limit": 1000}).json()
        open_ = {
            (a["task_id"], a["robot"])
            for a in state["assignments"]
            if not (a.get("execution") or {}).get("state")
        }
        robots = httpx.get(f"{server.url}/fleet/robots").json()
        return f"head {head} {state['status']}; unreported {sorted(open_)}; fleet {robots}"

    states: dict[str, str] = eventually(
        lambda: reported(server, run_id),
        until=lambda s: len(s) == n and all(v in ("done", "failed") for v in s.values()),
        timeout=timeout,
        what=f"all {n} tasks of {run_id} reported done or failed by the robots",
        context=context,
    )
    return states


def test_a_120_task_run_is_executed_by_six_simulated_robots(
    fleet: tuple[Server, Simulator], recorder: Recorder
) -> None:
    server, _sim = fleet
    server.start()
    online(server)
    run_id = httpx.post(f"{server.url}/runs", json=body(120)).json()["id"]
    states = all_final(server, run_id, 120)
    assert set(states.values()) == {"done", "failed"}  # a fifth of the actions fail
    assert recorder.invalid == []
    published = recorder.orders_published()
    assert len(published) == 120 and max(published.values()) == 1
    # The site learned from the robots' reports: one outcome per task.
    estimates = httpx.get(f"{server.url}/sites/default/estimates").json()
    counted = sum(
        f["successes"] + f["failures"] for r in estimates["robots"] for f in r["features"]
    )
    assert counted >= 120
    assert {
        r["serial_number"] for r in httpx.get(f"{server.url}/fleet/robots").json()["robots"]
    } == set(ROBOTS)


def test_a_server_killed_mid_run_sends_every_order_once(
    fleet: tuple[Server, Simulator], recorder: Recorder
) -> None:
    server, _sim = fleet
    held = PausePoint(60, "reason", after=False)
    server.start(pause=held)
    online(server)
    run_id = httpx.post(f"{server.url}/runs", json=body(120)).json()["id"]
    server.wait_for_log(held.message())
    # Orders for the first 60 decisions flow while the run is held; some are done.
    eventually(
        lambda: reported(server, run_id),
        until=lambda s: sum(v in ("done", "failed") for v in s.values()) >= 12,
        what="a dozen tasks reported before the kill",
    )
    server.kill()
    server.start()
    states = all_final(server, run_id, 120)
    assert len(states) == 120
    assert httpx.get(f"{server.url}/runs/{run_id}").json()["status"] == "completed"
    assert recorder.invalid == []
    published = recorder.orders_published()
    assert len(published) == 120, "an order was lost or one too many was made"
    twice = {k: v for k, v in published.items() if v > 1}
    assert twice == {}, f"orders published twice: {twice}"


def test_robot_3_broken_is_revised_away(
    fleet: tuple[Server, Simulator], recorder: Recorder
) -> None:
    server, sim = fleet
    server.start()
    online(server)
    run_id = httpx.post(f"{server.url}/runs", json=body(60)).json()["id"]
    eventually(
        lambda: sim.lines(),
        until=lambda text: "robot-3 FINISHED" in text or "robot-3 FAILED" in text,
        what="robot-3 at work",
    )
    sim.say("break robot-3")
    eventually(
        lambda: [
            m.body["connectionState"] for m in recorder.of("connection") if "/robot-3/" in m.topic
        ],
        until=lambda states: "CONNECTIONBROKEN" in states,
        what="robot-3's will on the broker",
    )
    head = eventually(
        lambda: httpx.get(f"{server.url}/runs/{run_id}").json().get("superseded_by"),
        what="a revision of the run without robot-3",
    )
    revision = httpx.get(f"{server.url}/runs/{head}").json()
    assert revision["revision_of"] == run_id
    states = all_final(server, run_id, 60)
    assert len(states) == 60
    final = httpx.get(f"{server.url}/runs/{head}", params={"limit": 1000}).json()
    later = [a for a in final["assignments"] if a["robot"] == "robot-3" and not a.get("pinned")]
    assert later == []
    assert recorder.invalid == []
