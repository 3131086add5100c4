"""docs/estimates.md#counting-each-report-once on PostgreSQL with two server processes: reports sent
to either (the same report to both at once too, each step together) end up in one set of
estimates, nothing counted twice; a stale `started` is refused; bad input is refused there as
on SQLite, and stores nothing."""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from threading import Barrier

import httpx
import pytest

from tests.sites.test_sites_e2e import BASELINE, estimates, report, run, steps
from tests.support.postgres import fresh_database, query
from tests.support.server import Server
from tests.support.site_support import Tally, assert_matches, baseline_features, baseline_rates

pytestmark = pytest.mark.e2e


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    with fresh_database("ltaa_sites") as url:
        yield url


def test_reports_to_either_process_make_one_set_of_estimates(
    tmp_path: Path, postgres_url: str
) -> None:
    features, priors = baseline_features(), baseline_rates()
    env = {"LTAA_DATABASE_URL": postgres_url, "LTAA_CLAIM_POLL_S": "0.5"}
    a = Server(tmp_path / "a", env={**env, "LTAA_WORKER_NAME": "api-a"})
    b = Server(tmp_path / "b", env={**env, "LTAA_WORKER_NAME": "api-b"})
    try:
        a.start()
        b.start()
        with a.client() as ca, b.client() as cb:
            one = run(a, ca, site="s1")
            two = run(b, cb, site="s1")
            tally = Tally()
            to_a = {"0": "done", "1": "failed", "2": "done"}
            to_b = {"3": "failed", "4": "done", "5": "done"}
            report(ca, one["id"], to_a)
            report(cb, one["id"], to_b)
            tally.add_reports(one["assignments"], {**to_a, **to_b}, features)
            # The same report to both processes at once, step by step (`started`, then the
            # outcomes): each step is stored once, its copy a no-op. A `started` sent after
            # the task ended is stale, a 409 (docs/living-plans.md#execution-reports): a
            # client sends each task's steps in order, so the steps are not raced here.
            both = {"6": "failed", "7": "done", "8": "failed"}
            together = Barrier(2)

            def step(c: httpx.Client, updates: list[dict[str, object]]) -> httpx.Response:
                together.wait(timeout=30)
                return c.post(f"/runs/{two['id']}/execution", json={"updates": updates})

            for updates in steps(both):
                with ThreadPoolExecutor(2) as pool:
                    answers = list(pool.map(step, (ca, cb), (updates, updates)))
                assert [r.status_code for r in answers] == [200, 200], [r.text for r in answers]
            tally.add_reports(two["assignments"], both, features)
            stale = cb.post(f"/runs/{two['id']}/execution", json={"updates": steps(both)[0][:1]})
            assert stale.status_code == 409
            assert stale.json()["detail"][0]["loc"] == ["body", "updates", 0, "state"]
            seen_a, seen_b = estimates(ca, "s1"), estimates(cb, "s1")
            assert seen_a["robots"] == seen_b["robots"] and seen_a["reports"] == 9
            assert_matches(seen_a, tally, priors)
            # Bad input, refused by either process; nothing stored.
            runs_before = query(postgres_url, "SELECT count(*) FROM runs")[0][0]
            refused = cb.post("/runs", json={**BASELINE, "site": "s1", "rates": "learnt"})
            assert refused.status_code == 422
            assert refused.json()["detail"][0]["loc"] == ["body", "rates"]
            assert ca.get("/sites/elsewhere/estimates").status_code == 404
            no_offset = cb.get("/sites/s1/estimates", params={"as_of": "2026-12-01T09:30"})
            assert no_offset.status_code == 422
            assert query(postgres_url, "SELECT count(*) FROM runs")[0][0] == runs_before
        rows = query(
            postgres_url, "SELECT count(*), count(DISTINCT (run_id, task_index)) FROM site_reports"
        )
        assert rows[0] == (9, 9)
    finally:
        a.stop()
        b.stop()
