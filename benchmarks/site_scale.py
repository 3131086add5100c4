"""The read at scale (docs/estimates.md#sites): the estimates of a site with 100,000 reports,
through the API and in the service, on the embedded SQLite store (part of
benchmarks.site_learning)."""

from __future__ import annotations

import hashlib
import statistics
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
from fastapi.testclient import TestClient
from sqlalchemy import insert

from app.config import Settings
from app.main import create_app


@contextmanager
def served() -> Iterator[TestClient]:
    with tempfile.TemporaryDirectory(prefix="ltaa-sites-bench-") as tmp:
        settings = Settings(data_dir=Path(tmp), log_level="WARNING", max_concurrent_runs=2)
        with TestClient(create_app(settings)) as client:
            yield client


def wait(client: TestClient, run_id: str) -> dict[str, Any]:
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        state: dict[str, Any] = client.get(f"/runs/{run_id}").json()
        if state["status"] == "completed":
            return state
        if state["status"] in ("failed", "cancelled"):
            raise RuntimeError(f"run {run_id} ended {state['status']}: {state['error']}")
        time.sleep(0.02)
    raise TimeoutError(f"run {run_id} did not complete")


def estimate_latency(reports: int = 100_000, repeats: int = 7) -> dict[str, float]:
    """Median seconds of GET /sites/{site}/estimates over a site with `reports` outcome rows
    (written as the reports would write them, in bulk), and of the service call alone."""
    from app.sites.service import site_estimates
    from app.store.site_models import SiteReport

    with served() as client:
        run = client.post(
            "/runs", json={"scenario": "baseline", "site": "big", "reasoner": "rules"}
        )
        run_id = run.json()["id"]
        wait(client, run_id)
        sessions = client.app.state.runs.sessions  # type: ignore[attr-defined]
        rng = np.random.default_rng(0)
        robots = ["light", "medium", "heavy"]
        kinds = [
            ("Motion", '["dexterous"]'),
            ("ObjectInteraction", '["heavy"]'),
            ("Motion", '["careful", "heavy"]'),
            ("Audio", '["careful"]'),
        ]
        t0 = datetime(2026, 1, 1, tzinfo=UTC)
        rows = []
        for i in range(reports):
            kind, feats = kinds[i % len(kinds)]
            minutes = float(rng.lognormal(3.0, 0.4))
            p = float(rng.uniform(0.3, 0.95))
            rows.append(
                {
                    "site": "big",
                    "run_id": run_id,
                    "task_index": 1000 + i,
                    "task_id": str(i),
                    "robot": robots[i % 3],
                    "task_type": kind,
                    "features": feats,
                    "feature_set": hashlib.sha256(feats.encode()).hexdigest(),
                    "success": bool(rng.random() < p),
                    "predicted": p,
                    "predicted_bin": int(p * 10),
                    "reported_at": t0 + timedelta(minutes=i),
                    "received_at": t0 + timedelta(minutes=i),
                    "minutes": minutes,
                    "log_minutes": float(np.log(minutes)),
                    "planned_minutes": 20.0,
                }
            )
        with sessions.begin() as session:
            session.execute(insert(SiteReport), rows)
        api, service = [], []
        for _ in range(repeats):
            began = time.perf_counter()
            answer = client.get("/sites/big/estimates")
            api.append(time.perf_counter() - began)
            assert answer.json()["reports"] == reports
            began = time.perf_counter()
            site_estimates(sessions=sessions, site="big", strength=10.0)
            service.append(time.perf_counter() - began)
        as_of = (t0 + timedelta(minutes=reports // 2)).isoformat()
        began = time.perf_counter()
        half = client.get("/sites/big/estimates", params={"as_of": as_of}).json()
        half_s = time.perf_counter() - began
        assert half["reports"] == reports // 2 + 1
    return {
        "api": statistics.median(api),
        "service": statistics.median(service),
        "as_of": half_s,
    }
