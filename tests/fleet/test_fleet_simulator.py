"""The simulator as the README starts it (docs/fleet.md#the-simulator): in the background with
`< /dev/null`, its robots work on after the end of its input, and stop, each saying OFFLINE, at
SIGTERM."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.mqtt_broker import Recorder
from tests.support.polling import eventually
from tests.support.server import ROOT

pytestmark = pytest.mark.e2e

ROBOTS = ("left", "right")


def test_the_end_of_its_input_is_not_the_end_of_its_robots(
    mqtt_url: str, interface: str, recorder: Recorder, tmp_path: Path
) -> None:
    log = tmp_path / "simulator.log"
    with log.open("wb") as out:
        proc = subprocess.Popen(
            [
                *(sys.executable, "-m", "app.cli", "fleet", "simulate", "--url", mqtt_url),
                *("--interface", interface, "--names", ",".join(ROBOTS)),
                *("--state-interval-s", "0.1"),
            ],
            cwd=ROOT,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        eventually(
            log.read_text,
            until=lambda text: "end of commands" in text,
            what="the simulator reading the end of its input",
        )
        # A second of state from each robot after that, and nobody gone.
        heard = eventually(
            lambda: [m.topic.split("/")[-2] for m in recorder.of("state")],
            until=lambda names: all(names.count(r) >= 10 for r in ROBOTS),
            what="ten states from each robot",
        )
        assert set(heard) == set(ROBOTS)
        assert [
            m.body for m in recorder.of("connection") if m.body["connectionState"] != "ONLINE"
        ] == []
        assert proc.poll() is None
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0
        gone = eventually(
            lambda: {
                m.topic.split("/")[-2]
                for m in recorder.of("connection")
                if m.body["connectionState"] == "OFFLINE"
            },
            until=lambda names: names == set(ROBOTS),
            what="each robot saying OFFLINE",
        )
        assert gone == set(ROBOTS)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
