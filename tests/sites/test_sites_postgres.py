"""docs/estimates.md#counting-each-report-once on PostgreSQL with two server processes: reports sent
to either (the same report to both at once too) end up in one set of estimates, nothing counted
twice; bad input is refused there as on SQLite, and stores nothing."""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from tests.sites.test_sites_e2e import BASELINE, estimates, report, run
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
            # The same outcomes to both processes at once: one is stored, the other a no-op.
            both = {"6": "failed", "7": "done", "8": "failed"}
            with ThreadPoolExecutor(2) as pool:
                list(pool.map(lambda c: report(c, two["id"], both), (ca, cb)))
            tally.add_reports(two["assignments"], both, features)
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
