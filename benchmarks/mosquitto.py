"""A mosquitto broker of one's own on a free loopback port (Debian's /usr/sbin/mosquitto), for
the fleet benchmark and the tests (docs/fleet.md#a-broker-by-hand)."""

from __future__ import annotations

import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

MOSQUITTO = "/usr/sbin/mosquitto"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextmanager
def broker(*, unlimited_queues: bool = False, log_to: Path | None = None) -> Iterator[str]:
    """Its URL, mqtt://127.0.0.1:{port}; stopped on exit. `unlimited_queues`: no message a
    slow subscriber has not taken yet is dropped (mosquitto keeps 1,000 a client by default),
    so a throughput figure counts every message. `log_to`: where its log goes (its notices
    too, e.g. a client id taken over: "already connected"); default a temporary file."""
    binary = shutil.which("mosquitto") or MOSQUITTO
    if not Path(binary).exists():
        raise RuntimeError("mosquitto is missing: apt-get install -y mosquitto")
    port = free_port()
    with tempfile.TemporaryDirectory(prefix="ltaa-mosquitto-") as tmp:
        conf = Path(tmp) / "mosquitto.conf"
        lines = [f"listener {port} 127.0.0.1", "allow_anonymous true", "persistence false"]
        if unlimited_queues:
            lines += ["max_queued_messages 0", "max_inflight_messages 0"]
        conf.write_text("\n".join(lines) + "\n")
        log = (log_to or Path(tmp) / "mosquitto.log").open("wb")
        proc = subprocess.Popen([binary, "-c", str(conf)], stdout=log, stderr=subprocess.STDOUT)
        try:
            deadline = time.monotonic() + 10
            while True:
                if proc.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"mosquitto did not start on port {port}")
                try:
                    with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                        break
                except OSError:
                    time.sleep(0.05)
            yield f"mqtt://127.0.0.1:{port}"
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
            log.close()
