"""The exact expected-success / balance frontier of a run's instance, and where the run
sits on it.

A 10,000-task run has thousands of possible caps, so the frontier is the exact optimum at a
bounded number of them: at most MAX_CAPS points, spread from cap 0 to the deviation of the
uncapped optimum, plus the run's own cap and no cap. It depends only on the run's stored
request, so it is computed once per run and kept as a small JSON file in the data directory.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

from app.domain.cap import WorkloadCap
from app.domain.metrics import balance_score, max_abs_deviation, workload
from app.runs.spec import RunSpec
from app.solvers.optimal import best_completion

MAX_CAPS = 12
CACHE_VERSION = 1


@dataclass(frozen=True)
class FrontierPoint:
    max_deviation: float | None  # None: no cap
    expected_success: float  # mean S of the optimum at this cap, 0..1
    balance_score: float  # 0..100


def caps_to_try(top: float, own: float | None) -> list[float]:
    """Caps spread over [0, top] and the run's own cap: with no cap, MAX_CAPS in all."""
    steps = MAX_CAPS - 3  # MAX_CAPS - 2 spread points, the run's own cap, no cap
    caps = {round(top * i / steps, 2) for i in range(steps + 1)}
    if own is not None:
        caps.add(own)
    return sorted(caps)


def compute_frontier(spec: RunSpec) -> list[FrontierPoint]:
    instance = spec.problem.instance
    success = instance.success
    n, r = instance.n_tasks, instance.n_robots

    def optimum(cap: WorkloadCap) -> tuple[FrontierPoint, float]:
        assignment, total = best_completion(success, cap)
        loads = workload(assignment, r)
        point = FrontierPoint(cap.max_deviation, total / n, balance_score(loads, n / r))
        return point, max_abs_deviation(loads, n / r)

    uncapped, top = optimum(WorkloadCap(n, r, None))
    points = []
    for k in caps_to_try(float(math.ceil(top)), spec.max_deviation):
        cap = WorkloadCap(n, r, k)
        if cap.infeasibility() is None:  # e.g. cap 0 when n / r is not whole
            points.append(optimum(cap)[0])
    return [*points, uncapped]


def _path(cache_dir: Path, run_id: str) -> Path:
    return cache_dir / f"frontier-{run_id}.json"


def cached_frontier(*, run_id: str, cache_dir: Path) -> list[FrontierPoint] | None:
    """The run's frontier if it has been computed, else None (nothing is computed)."""
    try:
        cached = json.loads(_path(cache_dir, run_id).read_text())
        if cached.get("version") == CACHE_VERSION:
            return [FrontierPoint(**p) for p in cached["points"]]
    except (OSError, ValueError, TypeError, KeyError):
        pass  # absent or unreadable: computed again
    return None


def frontier(*, spec: RunSpec, run_id: str, cache_dir: Path) -> list[FrontierPoint]:
    """The cached frontier of a run, computed on first use."""
    cached = cached_frontier(run_id=run_id, cache_dir=cache_dir)
    if cached is not None:
        return cached
    path = _path(cache_dir, run_id)
    points = compute_frontier(spec)
    cache_dir.mkdir(parents=True, exist_ok=True)
    # Written whole then renamed, so a concurrent reader never sees half a file.
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(json.dumps({"version": CACHE_VERSION, "points": [asdict(p) for p in points]}))
    tmp.replace(path)
    return points
