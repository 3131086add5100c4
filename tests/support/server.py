"""A real server for end-to-end tests: scripts/serve.sh (uvicorn; the app migrates as it
starts) in a subprocess on a free loopback port, exactly as `make run` starts it; stoppable
with SIGKILL."""

from __future__ import annotations

import codecs
import os
import random
import signal
import socket
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx

from app.graph.pause import PausePoint
from tests.support.polling import eventually

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
LLM_ENVIRONMENT = (
    "ANTHROPIC_API_KEY",
    "LTAA_ANTHROPIC_API_KEY",
    "LTAA_ANTHROPIC_BASE_URL",
    "LTAA_OPENAI_BASE_URL",
    "LTAA_OPENAI_API_KEY",
    "LTAA_OPENAI_MODEL",
)


# Ports below the kernel's ephemeral range: bind(("127.0.0.1", 0)) and every outgoing
# connection take theirs from that range, so a port drawn here is not handed to a client
# socket while it waits to be listened on. Drawn at random (SystemRandom: a test seeding
# `random` cannot make the pytest-xdist workers draw the same ports), so two workers rarely
# draw the same one; when they do, Server.start takes another.
_PORTS = range(10_000, 32_768)


def _ephemeral_low() -> int:
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return _PORTS.stop


def free_port() -> int:
    """A loopback port nothing is bound to at the moment of asking."""
    draw = random.SystemRandom()
    ports = range(_PORTS.start, min(_PORTS.stop, _ephemeral_low()))
    for _ in range(200):
        port = draw.choice(ports)
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise RuntimeError(f"no free loopback port in {ports} after 200 draws")


# The longest pause between two polls of a server (polls back off to it from 10 ms): a GET
# /runs/{id} costs the server CPU, taken from the run it watches. 0.25 s for a state that
# stays (a run finished, or held at a pause point: the awaited log line stays logged);
# 0.05 s where the test acts on a moving run at a progress threshold.
SETTLED_POLL_S = 0.25
TRANSIENT_POLL_S = 0.05

# What uvicorn logs once it listens, and what it logs when another process holds the port.
LISTENING = "Uvicorn running on http://127.0.0.1:{port} "
PORT_TAKEN = "address already in use"


def pause_setting(point: PausePoint) -> str:
    """`LTAA_TEST_PAUSE` for `point`: a server started with it logs `point.message()`."""
    setting = f"{point.task_index}:{point.node}:{'after' if point.after else 'before'}"
    assert PausePoint.from_setting(setting) == point  # the server reads back this point
    return setting


class PortTaken(Exception):
    """Another process bound the server's port between free_port() and the server's bind."""


class LogReader:
    """What a server has logged since `start` bytes into its log file, read incrementally:
    each call reads only what was appended since the last one (a SIGKILL suite's log holds
    eleven starts, and a poll at 10 Hz used to re-read all of it each time)."""

    def __init__(self, path: Path, start: int) -> None:
        self._path = path
        self._offset = start
        self._decode = codecs.getincrementaldecoder("utf-8")(errors="replace").decode
        self.text = ""

    def read(self) -> str:
        """Everything logged since `start` (appending what is new)."""
        with self._path.open("rb") as f:
            f.seek(self._offset)
            new = f.read()
        self._offset += len(new)
        self.text += self._decode(new)
        return self.text

    def count(self, text: str) -> int:
        self.read()
        return self.text.count(text)


class Server:
    def __init__(
        self,
        data_dir: Path,
        env: dict[str, str] | None = None,
        port: int | None = None,
        *,
        root: Path = ROOT,
    ) -> None:
        """`root`: the source tree to serve; another than this checkout (an earlier release,
        say) is put first on the server's path."""
        self.data_dir = data_dir
        self.root = root
        self.fixed_port = port is not None  # a port the test chose is never replaced
        self.port = port or free_port()
        self.env = {**os.environ, "LTAA_DATA_DIR": str(data_dir), **(env or {})}
        if root != ROOT:
            self.env["PYTHONPATH"] = str(root)
        # The developer's own LLM configuration stays out of the server under test.
        for key in (*LLM_ENVIRONMENT, *(k for k in os.environ if k.startswith("OPENAI_"))):
            if key not in (env or {}):
                self.env.pop(key, None)
        self.proc: subprocess.Popen[bytes] | None = None
        self.log = data_dir / f"server-{self.port}.log"
        self._log_start = 0  # where the latest start's output begins in `log`
        self._logged = LogReader(self.log, 0)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(
        self, timeout: float = 120.0, *, pause: PausePoint | None = None, **env: str
    ) -> Server:
        """Start the server and wait until it listens on its port and /health answers;
        `pause` holds its runs there (LTAA_TEST_PAUSE): wait for
        `wait_for_log(pause.message())` before acting on it.

        Tests run in parallel (pytest-xdist), and a port found free may be taken before the
        server binds it: the server then exits saying so, and is started again on another
        port (`port` and `url` name the one it listens on)."""
        self.data_dir.mkdir(parents=True, exist_ok=True)
        if pause is not None:
            env["LTAA_TEST_PAUSE"] = pause_setting(pause)
        for _ in range(5):
            try:
                return self._start(timeout, env)
            except PortTaken:
                if self.fixed_port:
                    raise
                self.port = free_port()
        raise RuntimeError(
            f"five ports in a row were taken before the server bound them:\n{self._log_tail()}"
        )

    def _start(self, timeout: float, env: dict[str, str]) -> Server:
        full_env = {
            **self.env,
            **env,
            "LTAA_BIN": f"{BIN}/",
            "HOST": "127.0.0.1",
            "PORT": str(self.port),
        }
        self._log_start = self.log.stat().st_size if self.log.exists() else 0
        self._logged = LogReader(self.log, self._log_start)
        with self.log.open("ab") as log:
            # The script `make run` and the Docker image use; it execs uvicorn, so this
            # process is the server and SIGKILL reaches it directly.
            self.proc = subprocess.Popen(
                ["sh", str(self.root / "scripts" / "serve.sh")],
                cwd=self.root,
                env=full_env,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        try:
            eventually(
                self._healthy,
                timeout=timeout,
                interval=0.1,
                what=f"the server on port {self.port} answering GET /health",
                context=self._log_tail,
            )
        except BaseException:
            self.kill()  # a server that did not come up in time is not left running
            raise
        return self

    def _healthy(self) -> bool:
        assert self.proc is not None
        if self.proc.poll() is not None:
            if PORT_TAKEN in self.logged():
                raise PortTaken(self.port)
            raise RuntimeError(f"server exited early:\n{self._log_tail()}")
        # Until this process says it listens, whatever answers on the port is another's.
        if LISTENING.format(port=self.port) not in self.logged():
            return False
        try:
            return httpx.get(f"{self.url}/health", timeout=1).status_code == 200
        except httpx.HTTPError:
            return False

    def _log_tail(self) -> str:
        return self.log.read_text()[-3000:]

    def logged(self) -> str:
        """What the server has logged since it was last started."""
        return self._logged.read()

    def kill(self) -> None:
        """SIGKILL: no shutdown hooks, no flushing — a crash."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(timeout=30)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.kill()

    def client(self) -> httpx.Client:
        return httpx.Client(base_url=self.url, timeout=30)

    def wait_for(
        self,
        run_id: str,
        predicate: Callable[[dict[str, Any]], object],
        timeout: float = 120.0,
        *,
        headers: dict[str, str] | None = None,
        page: int | None = None,
        interval: float = SETTLED_POLL_S,
    ) -> dict[str, Any]:
        """The run's state (GET /runs/{id}) once `predicate` holds for it. `page`: at most
        that many assignments per poll (the `limit` query parameter); polling a run of
        hundreds of tasks for its progress need not serialise all of them at each poll.

        `interval`: the longest pause between polls (they start 10 ms apart and back off).
        The default suits a state the run stays in (finished, held at a pause point,
        blocked); a caller that acts on a moving run at a progress threshold (a kill at
        task n) passes TRANSIENT_POLL_S, or the run may be far past it, or done."""
        params = {} if page is None else {"limit": page}
        with self.client() as c:
            state: dict[str, Any] = eventually(
                lambda: c.get(f"/runs/{run_id}", headers=headers, params=params).json(),
                until=predicate,
                timeout=timeout,
                interval=interval,
                what=f"run {run_id} satisfied {getattr(predicate, '__name__', predicate)}",
            )
        return state

    def wait_for_log(self, text: str, *, count: int = 1, timeout: float = 60.0) -> None:
        """Until the server, since its latest start, has logged `text` `count` times (e.g. a
        pause point's message once per run held there); fails at once if it has exited."""

        def seen() -> int:
            assert self.proc is not None and self.proc.poll() is None, self._log_tail()
            return self._logged.count(text)

        eventually(
            seen,
            until=lambda n: n >= count,
            timeout=timeout,
            interval=SETTLED_POLL_S,
            what=f"the server logged {text!r} {count} time(s)",
            context=self._log_tail,
        )
