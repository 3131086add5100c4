"""A real server for end-to-end tests: scripts/serve.sh (migrations, then uvicorn) in a
subprocess on a free loopback port, exactly as `make run` starts it; stoppable with SIGKILL."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx

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


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    def __init__(
        self, data_dir: Path, env: dict[str, str] | None = None, port: int | None = None
    ) -> None:
        self.data_dir = data_dir
        self.port = port or free_port()
        self.env = {**os.environ, "LTAA_DATA_DIR": str(data_dir), **(env or {})}
        # The developer's own LLM configuration stays out of the server under test.
        for key in (*LLM_ENVIRONMENT, *(k for k in os.environ if k.startswith("OPENAI_"))):
            if key not in (env or {}):
                self.env.pop(key, None)
        self.proc: subprocess.Popen[bytes] | None = None
        self.log = data_dir / f"server-{self.port}.log"

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout: float = 60.0, **env: str) -> Server:
        self.data_dir.mkdir(parents=True, exist_ok=True)
        full_env = {
            **self.env,
            **env,
            "LTAA_BIN": f"{BIN}/",
            "HOST": "127.0.0.1",
            "PORT": str(self.port),
        }
        with self.log.open("ab") as log:
            # The script `make run` and the Docker image use; it execs uvicorn, so this
            # process is the server and SIGKILL reaches it directly.
            self.proc = subprocess.Popen(
                ["sh", str(ROOT / "scripts" / "serve.sh")],
                cwd=ROOT,
                env=full_env,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited early:\n{self.log.read_text()[-3000:]}")
            try:
                if httpx.get(f"{self.url}/health", timeout=1).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        raise RuntimeError(f"server did not become healthy:\n{self.log.read_text()[-3000:]}")

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

    def wait_for(self, run_id: str, predicate: Any, timeout: float = 120.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        last: dict[str, Any] = {}
        with self.client() as c:
            while time.monotonic() < deadline:
                last = c.get(f"/runs/{run_id}").json()
                if predicate(last):
                    return last
                time.sleep(0.05)
        raise AssertionError(f"timed out; last state: {last}")
