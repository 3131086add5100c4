"""Shared helpers: seeded synthetic instances, timing, markdown tables."""

from __future__ import annotations

import platform
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.domain.models import Instance, Robot, Task

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
IMG = DOCS / "img"


@dataclass
class Section:
    """One part of the report: a heading, markdown body, and the plots it drew."""

    title: str
    body: str
    images: list[str] = field(default_factory=list)


def synthetic_instance(
    n_tasks: int, n_robots: int, *, n_features: int = 3, seed: int = 0
) -> Instance:
    """Random robots (rates in [0.3, 1]) and tasks needing 1-3 random features."""
    rng = np.random.default_rng(seed)
    features = [f"f{i}" for i in range(n_features)]
    robots = tuple(
        Robot(
            name=f"robot{r}", success={f: float(round(rng.uniform(0.3, 1.0), 3)) for f in features}
        )
        for r in range(n_robots)
    )
    tasks = []
    for t in range(n_tasks):
        k = int(rng.integers(1, min(3, n_features) + 1))
        picked = tuple(sorted(rng.choice(features, size=k, replace=False).tolist()))
        tasks.append(Task(id=t, name=f"task{t}", features=picked))
    return Instance(tasks=tuple(tasks), robots=robots)


def median_seconds(fn: Callable[[], Any], repeats: int, warmup: int = 1) -> float:
    for _ in range(warmup):
        fn()
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - start)
    return statistics.median(samples)


def fmt_time(seconds: float) -> str:
    if seconds < 1e-3:
        return f"{seconds * 1e6:.0f} µs"
    if seconds < 1:
        return f"{seconds * 1e3:.2f} ms"
    return f"{seconds:.2f} s"


def table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def machine() -> str:
    import os

    return (
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}"
    )


def write_section(title: str, text: str) -> None:
    """Replace (or append) the section of docs/benchmarks.md that starts with `title`,
    leaving every other section as it is: the console and exchange benchmarks run on their
    own, apart from `make bench`."""
    path = DOCS / "benchmarks.md"
    report = path.read_text(encoding="utf-8") if path.exists() else "# Benchmarks\n"
    start = report.find(title)
    if start >= 0:
        end = report.find("\n## ", start + len(title))
        report = report[:start] + text + ("" if end < 0 else report[end:])
    else:
        report = report.rstrip("\n") + "\n\n" + text
    path.write_text(report, encoding="utf-8")


def revision() -> str:
    """The app's revision: the last commit that changed app/, "+changes" when app/ has
    uncommitted changes (a kept row says which model produced it; a docs or benchmark
    commit leaves it)."""
    import subprocess

    def git(*args: str) -> str:
        done = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)
        return done.stdout.strip()

    head = git("log", "-1", "--format=%h", "--", "app") or "unknown"
    return head + ("+changes" if git("status", "--porcelain", "--", "app") else "")


def _revisions(rows: Sequence[dict[str, Any]]) -> list[str]:
    return list(dict.fromkeys(str(r.get("revision", "before revisions were kept")) for r in rows))


def stale_mark(rows: Sequence[dict[str, Any]], row: dict[str, Any]) -> str:
    """ " †" on a kept row measured at another revision than the newest row's."""
    revisions = _revisions(rows)
    return " †" if len(revisions) > 1 and row.get("revision") != revisions[-1] else ""


def revision_line(rows: Sequence[dict[str, Any]], what: str) -> str:
    """Which revision measured the rows (`what` with a {} for the commit)."""
    revisions = _revisions(rows)
    if not revisions:
        return ""
    newest = [r for r in rows if r.get("revision", "before revisions were kept") == revisions[-1]]
    if len(revisions) == 1:
        return f"Every row measured by {what.format(revisions[0])}."
    older = len(rows) - len(newest)
    return (
        f"{len(newest)} rows measured by {what.format(revisions[-1])}; the {older} rows marked "
        f"† by earlier revisions ({', '.join(revisions[:-1])})."
    )
