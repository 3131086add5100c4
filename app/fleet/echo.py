"""The bridge's echo session (docs/fleet.md#delivery): its own orders and instant actions back
from the broker, each marking its outbox row published.

A persistent MQTT session (clean_session off) that acknowledges a message only once its mark is
committed (manual acks): a message published just before the server was killed, and not yet
marked, is either unacknowledged here or not yet delivered, and the broker hands it to this
session again at the next start. A fence (a message on a topic of the bridge's own, published
after subscribing) arrives after all of those: one session's messages arrive in order. So the
publisher, waiting for the fence before it sends, never sends a message twice.

Its client id is the active bridge's (`{client id}-echo`, docs/fleet.md#client-ids), taken over
with the lease: a new holder finds the session of a holder that died, with what that one
published and did not mark. A standby never connects under it.

paho-mqtt directly (aiomqtt acknowledges on receipt); its network loop runs in its own thread.
"""

from __future__ import annotations

import json
import logging
import threading
import time
import uuid

import paho.mqtt.client as mqtt
from sqlalchemy.orm import Session, sessionmaker

from app.fleet import outbox
from app.fleet.vda5050 import Topic, subscription

log = logging.getLogger("ltaa.fleet")


class EchoSession:
    def __init__(
        self,
        *,
        host: str,
        port: int,
        tls: bool,
        identifier: str,
        interface: str,
        sessions: sessionmaker[Session],
    ) -> None:
        self.sessions = sessions
        self.interface = interface
        self.fence = f"ltaa-fence/{identifier}/{uuid.uuid4().hex}"
        self.caught_up = threading.Event()
        self.client = mqtt.Client(
            mqtt.CallbackAPIVersion.VERSION2,
            client_id=identifier,
            clean_session=False,
            manual_ack=True,
        )
        if tls:
            self.client.tls_set()
        self.client.on_connect = self._on_connect
        self.client.on_message = self._on_message
        self.host, self.port = host, port

    def start(self) -> None:
        self.client.connect_async(self.host, self.port, keepalive=30)
        self.client.loop_start()

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()

    def _on_connect(self, client: mqtt.Client, *_args: object) -> None:
        self.caught_up.clear()
        topics = [
            (subscription(self.interface, k), 1) for k in (Topic.ORDER, Topic.INSTANT_ACTIONS)
        ]
        client.subscribe([*topics, (self.fence, 1)])
        # After the subscriptions: the broker sends it after what it kept for this session.
        client.publish(self.fence, b"{}", qos=1)

    def _on_message(
        self, client: mqtt.Client, _userdata: object, message: mqtt.MQTTMessage
    ) -> None:
        if message.topic == self.fence:
            self.caught_up.set()
            client.ack(message.mid, message.qos)
            return
        try:
            header = int(json.loads(message.payload)["headerId"])
        except (ValueError, KeyError, TypeError):
            client.ack(message.mid, message.qos)  # not one of ours
            return
        try:
            outbox.mark_seen(sessions=self.sessions, topic=message.topic, header_id=header)
        except Exception:  # unacknowledged: the broker sends it again at the next start
            log.exception("fleet echo: could not mark %s", message.topic)
            return
        client.ack(message.mid, message.qos)


def forget_session(host: str, port: int, tls: bool, identifier: str) -> None:
    """Drop a persistent session at the broker (a clean connect under its id, then a
    disconnect), so it stops keeping messages for a client that will not come back."""
    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=identifier, clean_session=True)
    if tls:
        client.tls_set()
    try:
        client.connect(host, port, keepalive=30)
        client.loop_start()
        for _ in range(100):  # up to 5 s for the CONNACK
            if client.is_connected():
                break
            time.sleep(0.05)
        client.disconnect()
    except OSError:
        log.warning("fleet echo: could not drop the session %s; the broker keeps it", identifier)
    finally:
        client.loop_stop()
