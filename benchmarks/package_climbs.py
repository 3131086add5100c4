"""How often a call path climbs back into a package it had left: one POST /runs through
TestClient, and the worker's run until its first trace row
(docs/development.md#the-walk-of-post-runs-and-the-worker).

Two counts, read on every call and return in every thread (sys.setprofile), library
frames (FastAPI, pydantic, SQLAlchemy) skipped:
- the walk: the package of the innermost app frame, repeats folded; a climb back is an
  entry into a package the walk had left (api -> runs -> store -> runs is one, the return
  from the store included);
- the stack: a call into a package already on the stack under another (the store calling
  back into runs); a plain return is none.
The worker's walk ends where its first trace row is written: its first call into
app.store.fenced, through which every decision and attempt row goes.

    python -m benchmarks.package_climbs
"""

from __future__ import annotations

import sys
import tempfile
import threading
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

WORKER_THREAD = "ltaa-run"  # app.runs.worker's thread_name_prefix
FIRST_TRACE_ROW = "app.store.fenced"


def package_of(module: str) -> str | None:
    """`app.<package>` of a module's dotted name (None outside app)."""
    if module == "app" or module.startswith("app."):
        return ".".join(module.split(".")[:2])
    return None


def stack_packages(frame: FrameType | None) -> list[str]:
    """The app packages on the stack from `frame` down, repeats folded, innermost first."""
    out: list[str] = []
    while frame is not None:
        package = package_of(frame.f_globals.get("__name__", ""))
        if package is not None and (not out or out[-1] != package):
            out.append(package)
        frame = frame.f_back
    return out


def walk_climbs(walk: list[str]) -> int:
    """Entries into a package the walk had left (the walk has its repeats folded)."""
    seen: set[str] = set()
    count = 0
    for i, package in enumerate(walk):
        if i and package in seen:
            count += 1
        seen.add(package)
    return count


@dataclass
class Walks:
    """The climbs back of each thread while recording is on, as the stacks they climbed."""

    recording: bool = False
    by_thread: dict[str, list[list[str]]] = field(default_factory=lambda: defaultdict(list))
    walks: dict[str, list[str]] = field(default_factory=lambda: defaultdict(list))
    worker_done: threading.Event = field(default_factory=threading.Event)

    def profile(self, frame: FrameType, event: str, arg: Any) -> None:
        if not self.recording or event not in ("call", "return"):
            return
        name = threading.current_thread().name
        worker = name.startswith(WORKER_THREAD)
        if worker and self.worker_done.is_set():
            return
        # On a return, execution is back in the innermost app frame below.
        inner = stack_packages(frame if event == "call" else frame.f_back)
        walk = self.walks[name]
        if inner and (not walk or walk[-1] != inner[0]):
            walk.append(inner[0])
        module = frame.f_globals.get("__name__", "")
        package = package_of(module)
        if event != "call" or package is None:
            return
        if worker and module == FIRST_TRACE_ROW:
            self.worker_done.set()
        caller = stack_packages(frame.f_back)
        if caller and caller[0] != package and package in caller:
            self.by_thread[name].append([package, *caller])

    def walk(self, worker: bool) -> list[str]:
        out: list[str] = []
        for name, walk in self.walks.items():
            if name.startswith(WORKER_THREAD) == worker:
                out.extend(walk)
        return out

    def request_climbs(self) -> list[list[str]]:
        return [
            c for n, cs in self.by_thread.items() if not n.startswith(WORKER_THREAD) for c in cs
        ]

    def worker_climbs(self) -> list[list[str]]:
        return [c for n, cs in self.by_thread.items() if n.startswith(WORKER_THREAD) for c in cs]


@contextmanager
def profiled(walks: Walks) -> Iterator[None]:
    threading.setprofile(walks.profile)
    sys.setprofile(walks.profile)
    try:
        yield
    finally:
        sys.setprofile(None)
        threading.setprofile(None)


Measured = tuple[list[str], list[list[str]]]  # the walk, the stack climbs


def measure() -> tuple[Measured, Measured]:
    """The walks of one POST /runs (the baseline scenario, rules) and of its worker."""
    from fastapi.testclient import TestClient

    from app.config import Settings
    from app.main import create_app

    walks = Walks()
    with tempfile.TemporaryDirectory() as tmp, profiled(walks):
        settings = Settings(
            data_dir=Path(tmp) / "data",
            anthropic_api_key=None,
            anthropic_base_url=None,
            openai_base_url=None,
            openai_api_key=None,
            openai_model=None,
        )
        with TestClient(create_app(settings)) as client:
            # FastAPI builds a route's dependencies on its first request (evaluating the
            # endpoint module's annotations): a refused POST /runs does that outside the walk.
            refused = client.post("/runs", json={"mode": "no such mode"})
            assert refused.status_code == 422, refused.text
            walks.recording = True
            created = client.post("/runs", json={"scenario": "baseline", "mode": "balanced"})
            request: Measured = (walks.walk(worker=False), walks.request_climbs())
            assert created.status_code == 202, created.text
            if not walks.worker_done.wait(60):
                raise RuntimeError("the worker wrote no trace row within 60 s")
            walks.recording = False
            return request, (walks.walk(worker=True), walks.worker_climbs())


def main() -> None:
    request, worker = measure()
    for label, (walk, stack_climbs) in (
        ("POST /runs", request),
        ("worker to its first trace row", worker),
    ):
        print(
            f"{label}: {walk_climbs(walk)} climbs back in the walk of {len(walk)} steps, "
            f"{len(stack_climbs)} calls back into a package lower on the stack"
        )
        print("  walk: " + " -> ".join(p.removeprefix("app.") for p in walk))
        for stack in stack_climbs:
            print("  stack: " + " <- ".join(p.removeprefix("app.") for p in stack))


if __name__ == "__main__":
    main()
