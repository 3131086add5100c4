"""Two API processes on one PostgreSQL database share the webhook outbox: every delivery
is attempted by one process at a time, and one killed with a delivery in flight has it
retried by the other once its claim expires."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterator
from itertools import pairwise
from pathlib import Path

import pytest
from cryptography.fernet import Fernet

from tests.fakes.webhook_receiver import running_receiver
from tests.support.polling import eventually
from tests.support.postgres import fresh_database, query
from tests.support.server import Server
from tests.webhooks.test_webhooks_e2e import FAST, start_run, subscribe

pytestmark = pytest.mark.e2e

CLAIM_S = 4.0


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    with fresh_database("ltaa_webhooks") as url:
        yield url


def wait_delivered(url: str, expected: int, timeout: float = 90) -> list[tuple[object, ...]]:
    return eventually(
        lambda: query(url, "SELECT id, state FROM webhook_deliveries"),
        until=lambda rows: len(rows) >= expected and all(r[1] == "delivered" for r in rows),
        what=f"{expected} deliveries, all delivered",
        timeout=timeout,
        interval=0.1,
    )


@pytest.mark.timeout(600)
def test_two_processes_share_the_outbox_and_take_over_a_dead_ones(
    tmp_path: Path, postgres_url: str
) -> None:
    env = {
        **FAST,
        "LTAA_DATABASE_URL": postgres_url,
        # Shared by both: either process must decrypt the secrets the other stored.
        "LTAA_SECRET_KEY": Fernet.generate_key().decode(),
        "LTAA_WEBHOOK_CONCURRENCY": "1",
        "LTAA_WEBHOOK_CLAIM_S": str(CLAIM_S),
        "LTAA_WEBHOOK_TIMEOUT_S": "3",
        "LTAA_LEASE_S": "3",
        "LTAA_CLAIM_POLL_S": "0.5",
    }
    a = Server(tmp_path / "a", env={**env, "LTAA_WORKER_NAME": "hooks-a"})
    b = Server(tmp_path / "b", env={**env, "LTAA_WORKER_NAME": "hooks-b"})
    with running_receiver(delay_s=0.3) as receiver:
        try:
            a.start()
            b.start()
            hook = subscribe(a, receiver.url)
            receiver.secret = hook["secret"]
            runs = [start_run(server) for server in (a, b, a, b, a, b)]
            for run_id in runs:
                a.wait_for(run_id, lambda s: s["status"] == "completed")
            rows = wait_delivered(postgres_url, 2 * len(runs))
            got = receiver.snapshot()
            # Exactly once here (no process died): one request per delivery, none twice.
            assert sorted(r.headers["webhook-id"] for r in got) == sorted(str(r[0]) for r in rows)
            workers = query(
                postgres_url,
                "SELECT delivery_id, count(DISTINCT worker), min(worker) FROM webhook_attempts "
                "GROUP BY delivery_id",
            )
            assert all(n == 1 for _, n, _ in workers)
            assert {str(w).split(":")[0] for _, _, w in workers} == {"hooks-a", "hooks-b"}

            # The process attempting a delivery dies in flight (the receiver is slow to
            # answer): the other retries it once the dead one's claim expires, never before.
            receiver.delay_s = 2.0
            last = start_run(a)
            claimed = eventually(
                lambda: query(
                    postgres_url,
                    "SELECT id, claim_expires_at, claimed_by FROM webhook_deliveries "
                    "WHERE run_id = %s AND claimed_by IS NOT NULL",
                    last,
                ),
                what="a delivery of the last run claimed (in flight)",
            )
            (stolen, claim_expires_at, claimer) = claimed[0]
            victim, survivor = (b, a) if str(claimer).startswith("hooks-b:") else (a, b)
            victim.kill()
            receiver.delay_s = 0.0
            survivor.wait_for(last, lambda s: s["status"] == "completed")
            wait_delivered(postgres_url, 2 * len(runs) + 2)
            attempts = query(
                postgres_url,
                "SELECT worker, started_at FROM webhook_attempts WHERE delivery_id = %s",
                stolen,
            )
        finally:
            a.kill()
            b.kill()
        # Only the survivor's attempt is logged: the victim died before recording its own.
        assert [str(w) for w, _ in attempts] != [] and not any(
            str(w) == str(claimer) for w, _ in attempts
        )
        assert {str(w).split(":")[0] for w, _ in attempts} == {
            "hooks-a" if survivor is a else "hooks-b"
        }
        assert attempts[0][1] >= claim_expires_at  # type: ignore[operator]
        assert str(stolen) in receiver.ids()
        # Never two attempts of one delivery at once at the receiver.
        spans = defaultdict(list)
        for r in receiver.snapshot():
            spans[r.headers["webhook-id"]].append((r.started, r.at))
        for intervals in spans.values():
            intervals.sort()
            assert all(prev[1] <= nxt[0] for prev, nxt in pairwise(intervals))
        receiver.verified(hook["secret"])
