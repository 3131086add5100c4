"""How many VDA 5050 state messages the fleet bridge takes a second (docs/fleet.md).

One mosquitto broker, one server started as `make run` starts it with the bridge on
(LTAA_MQTT_URL), 100 robots (one MQTT client each) that say ONLINE and then publish state
messages at QoS 1 as fast as the broker takes them. The figure is the bridge's: state messages
it validated and applied (ltaa_fleet_messages_total{topic="state"} on /metrics) over the time
from the first message published to the last one applied, beside the rate the robots
published at. Every message must arrive (the broker keeps unlimited queues): a round that
lost one reports nothing.

    python -m benchmarks.fleet_throughput [--robots 100] [--per-robot 1000]
"""

from __future__ import annotations

import argparse
import re
import tempfile
import threading
import time
from datetime import UTC, datetime
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import paho.mqtt.client as mqtt

from app.fleet.vda5050 import (
    PROTOCOL_VERSION,
    BatteryState,
    Connection,
    ConnectionState,
    SafetyState,
    State,
    Topic,
    topic,
)
from benchmarks.common import machine, table, write_section
from benchmarks.load import serve_process
from benchmarks.mosquitto import broker

INTERFACE = "bench"
MAKER = "bench"
TITLE = "## Fleet bridge throughput"
STATE_COUNT = re.compile(r'^ltaa_fleet_messages_total\{topic="state"\} ([0-9.e+]+)$', re.M)


def _client(url: str, name: str) -> mqtt.Client:
    parts = urlsplit(url)
    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"bench-{name}")
    client.max_inflight_messages_set(100)
    client.connect(parts.hostname or "127.0.0.1", parts.port or 1883)
    client.loop_start()
    return client


def _state(name: str, header: int) -> bytes:
    return State(
        header_id=header,
        timestamp=datetime.now(UTC),
        version=PROTOCOL_VERSION,
        manufacturer=MAKER,
        serial_number=name,
        order_id="",
        order_update_id=0,
        last_node_id="",
        last_node_sequence_id=0,
        node_states=[],
        edge_states=[],
        driving=False,
        action_states=[],
        battery_state=BatteryState(battery_charge=80.0, charging=False),
        operating_mode="AUTOMATIC",
        errors=[],
        safety_state=SafetyState(),
    ).wire()


def _applied(base: str) -> int:
    text = httpx.get(f"{base}/metrics", timeout=5).text
    match = STATE_COUNT.search(text)
    return int(float(match.group(1))) if match else 0


def measure(robots: int, per_robot: int) -> dict[str, float]:
    total = robots * per_robot
    with broker(unlimited_queues=True) as url, tempfile.TemporaryDirectory() as tmp:
        env = {
            "LTAA_MQTT_URL": url,
            "LTAA_MQTT_INTERFACE": INTERFACE,
            "LTAA_MQTT_MANUFACTURER": MAKER,
        }
        with serve_process(Path(tmp), env) as (base, _log, _pid):
            names = [f"robot-{i + 1}" for i in range(robots)]
            clients = {n: _client(url, n) for n in names}
            for n, c in clients.items():
                hello = Connection(
                    header_id=0,
                    timestamp=datetime.now(UTC),
                    version=PROTOCOL_VERSION,
                    manufacturer=MAKER,
                    serial_number=n,
                    connection_state=ConnectionState.ONLINE,
                )
                c.publish(topic(INTERFACE, MAKER, n, Topic.CONNECTION), hello.wire(), 1, True)
            deadline = time.monotonic() + 60
            while len(httpx.get(f"{base}/fleet/robots").json()["robots"]) < robots:
                if time.monotonic() > deadline:
                    raise RuntimeError("the robots' ONLINE did not all arrive")
                time.sleep(0.1)
            # The messages are built before the clock starts: the figure is the bridge's.
            batches = {n: [_state(n, h) for h in range(per_robot)] for n in names}
            start = time.monotonic()
            published: list[float] = []

            def send(name: str) -> None:
                client, name_topic = clients[name], topic(INTERFACE, MAKER, name, Topic.STATE)
                infos = [client.publish(name_topic, m, 1) for m in batches[name]]
                for info in infos:
                    info.wait_for_publish(timeout=120)

            threads = [threading.Thread(target=send, args=(n,)) for n in names]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            published.append(time.monotonic() - start)
            deadline = time.monotonic() + 600
            while (done := _applied(base)) < total:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"the bridge applied {done} of {total} state messages")
                time.sleep(0.05)
            elapsed = time.monotonic() - start
            for c in clients.values():
                c.loop_stop()
                c.disconnect()
    return {
        "robots": robots,
        "messages": total,
        "published_s": published[0],
        "applied_s": elapsed,
        "published_per_s": total / published[0],
        "applied_per_s": total / elapsed,
    }


def report(result: dict[str, float]) -> str:
    rows = [
        [
            f"{int(result['robots'])}",
            f"{int(result['messages']):,}",
            f"{result['published_per_s']:,.0f}",
            f"{result['applied_per_s']:,.0f}",
            f"{result['applied_s']:.1f} s",
        ]
    ]
    return (
        f"{TITLE}\n\n"
        "`python -m benchmarks.fleet_throughput`: one mosquitto, one server as `make run` starts "
        "it with the fleet bridge on (SQLite), robots that say ONLINE and then publish VDA 5050 "
        "`state` messages at QoS 1 as fast as the broker takes them. *Applied* counts the state "
        "messages the bridge validated and applied (`ltaa_fleet_messages_total`), from the first "
        "published to the last applied; every message arrived (target: at least 1,000 a "
        f"second). {machine()}.\n\n"
        + table(
            ["robots", "state messages", "published / s", "applied / s", "all applied in"], rows
        )
        + "\n"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=100)
    parser.add_argument("--per-robot", type=int, default=1000)
    parser.add_argument("--no-write", action="store_true", help="print, do not write the docs")
    args = parser.parse_args()
    result = measure(args.robots, args.per_robot)
    text = report(result)
    print(text)
    if not args.no_write:
        write_section(TITLE, text)


if __name__ == "__main__":
    main()
