"""A real MQTT broker for the fleet tests (docs/fleet.md#a-broker-by-hand), and a recorder of
what crosses it.

`LTAA_TEST_MQTT_URL` names one (.ci/run starts mosquitto and sets it); without it, each test
process starts its own mosquitto on a free loopback port. Every test takes its own topic
interface (`interface`), so tests sharing one broker never see each other's messages.
"""

from __future__ import annotations

import json
import os
import threading
import time
import uuid
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlsplit

import paho.mqtt.client as mqtt
import pytest

from benchmarks.mosquitto import broker
from tests.support.vda5050_schemas import validate


@pytest.fixture(scope="session")
def mqtt_url() -> Iterator[str]:
    given = os.environ.get("LTAA_TEST_MQTT_URL")
    if given:
        yield given
        return
    with broker() as url:
        yield url


@pytest.fixture
def interface() -> str:
    return f"t{uuid.uuid4().hex[:10]}"


@dataclass
class Seen:
    topic: str
    body: dict[str, Any]
    retain: bool
    at: float = field(default_factory=time.monotonic)  # when it arrived here


@dataclass
class Recorder:
    """Every message under `{interface}/#`, each checked against the VDA 5050 schema of its
    topic as it arrives (a message that fails is kept in `invalid`)."""

    url: str
    interface: str
    messages: list[Seen] = field(default_factory=list)
    invalid: list[tuple[str, str]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def start(self) -> Recorder:
        parts = urlsplit(self.url)
        self.client = mqtt.Client(
            mqtt.CallbackAPIVersion.VERSION2, client_id=f"rec-{uuid.uuid4().hex[:8]}"
        )
        subscribed = threading.Event()
        self.client.on_connect = lambda c, *_: c.subscribe(f"{self.interface}/#", qos=1)
        self.client.on_subscribe = lambda *_: subscribed.set()
        self.client.on_message = self._on_message
        self.client.connect(parts.hostname or "127.0.0.1", parts.port or 1883)
        self.client.loop_start()
        assert subscribed.wait(10), "the recorder could not subscribe"
        return self

    def stop(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()

    def _on_message(self, _c: mqtt.Client, _u: object, message: mqtt.MQTTMessage) -> None:
        kind = message.topic.rsplit("/", 1)[-1]
        try:
            body = json.loads(message.payload)
            validate(kind, body)
        except Exception as exc:  # kept for the test to report, whatever it was
            with self.lock:
                self.invalid.append((message.topic, repr(exc)[:300]))
            return
        with self.lock:
            self.messages.append(Seen(message.topic, body, bool(message.retain)))

    def of(self, kind: str) -> list[Seen]:
        with self.lock:
            return [m for m in self.messages if m.topic.endswith("/" + kind)]

    def orders_published(self) -> Counter[tuple[str, int]]:
        """How many times each (orderId, orderUpdateId) crossed the broker."""
        return Counter((m.body["orderId"], m.body["orderUpdateId"]) for m in self.of("order"))


@pytest.fixture
def recorder(mqtt_url: str, interface: str) -> Iterator[Recorder]:
    rec = Recorder(mqtt_url, interface).start()
    yield rec
    rec.stop()
