"""Run leases on a real PostgreSQL database, in process: claims never overlap, a process
that lost a lease writes nothing more, cancel and drain work across processes.

Two `RunWorker`s in one test process stand for two API processes: each has its own
lease owner id, checkpointer pool and threads, and they share only the database.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from alembic import command
from sqlalchemy import inspect
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.domain.catalog import scenario
from app.graph.checkpoint.postgres import open_postgres_saver
from app.runs import service
from app.runs.factory import make_worker
from app.runs.lifecycle import status_writes
from app.runs.ownership import LeaseOwnership
from app.runs.recorder import LeaseLost, RunStop, SqlRecorder
from app.runs.spec import RunSpec
from app.runs.worker import RunWorker
from app.store import decision_repository as decision_repo
from app.store import leases
from app.store import repository as repo
from app.store.db import make_engine, make_session_factory, transaction
from app.store.migrate import alembic_config, upgrade_head
from app.store.models import Run
from tests.support.factories import decision_record, run_row
from tests.support.polling import eventually
from tests.support.postgres import fresh_database, query

pytestmark = pytest.mark.e2e


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    with fresh_database("ltaa_leases") as url:
        upgrade_head(url)
        yield url


@pytest.fixture
def sessions(postgres_url: str) -> Iterator[sessionmaker[Session]]:
    engine = make_engine(postgres_url)
    yield make_session_factory(engine)
    engine.dispose()


@pytest.fixture
def make_leased(
    tmp_path: Path, postgres_url: str, sessions: sessionmaker[Session]
) -> Iterator[Callable[..., RunWorker]]:
    opened: list[RunWorker] = []

    def factory(**overrides: Any) -> RunWorker:
        settings = Settings(
            data_dir=tmp_path / "data",
            database_url=postgres_url,
            anthropic_api_key=None,
            anthropic_base_url=None,
            lease_s=0.9,
            claim_poll_s=0.2,
            **overrides,
        )
        worker = make_worker(settings=settings, sessions=sessions)
        assert isinstance(worker.ownership, LeaseOwnership)
        opened.append(worker)
        return worker

    yield factory
    for worker in opened:
        worker.close()


def lease(worker: RunWorker) -> LeaseOwnership:
    assert isinstance(worker.ownership, LeaseOwnership)
    return worker.ownership


def _create(sessions: sessionmaker[Session], worker: RunWorker) -> str:
    spec = RunSpec.for_instance(scenario("baseline").instance, mode="balanced")
    return service.create_run(
        sessions=sessions, worker=worker, settings=worker._settings, spec=spec
    ).id


def _run(sessions: sessionmaker[Session], run_id: str) -> Run:
    with sessions() as session:
        run = repo.get_run(session=session, run_id=run_id)
        assert run is not None
        return run


def _kinds(sessions: sessionmaker[Session], run_id: str) -> list[str]:
    with sessions() as session:
        return [e.kind for e in repo.events(session=session, run_id=run_id)]


def _decisions(sessions: sessionmaker[Session], run_id: str) -> int:
    with sessions() as session:
        return len(decision_repo.decisions(session=session, run_id=run_id))


def test_migrations_match_the_models_next_to_the_checkpointer_tables(postgres_url: str) -> None:
    _, close = open_postgres_saver(postgres_url, max_connections=2)
    close()
    engine = make_engine(postgres_url)
    tables = set(inspect(engine).get_table_names())
    engine.dispose()
    assert {"runs", "decisions", "checkpoints", "checkpoint_writes"} <= tables
    upgrade_head(postgres_url)  # idempotent, as every process start runs it
    command.check(alembic_config(postgres_url))  # raises if models and migrations differ


def test_concurrent_claims_never_overlap(sessions: sessionmaker[Session]) -> None:
    ids = [f"claim{i:02d}" for i in range(20)]
    with transaction(sessions) as session:
        session.add_all(run_row(i, "queued") for i in ids)
    barrier = threading.Barrier(4)
    claimed: dict[str, list[str]] = {}

    def claim(owner: str) -> None:
        barrier.wait()
        with transaction(sessions) as session:
            rows = leases.claim_runs(
                session=session, owner=owner, lease_s=60, limit=8, statuses=["queued"]
            )
        claimed[owner] = [r for r, _ in rows if r in ids]

    threads = [threading.Thread(target=claim, args=(f"p{n}",)) for n in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    everything = [r for rows in claimed.values() for r in rows]
    assert sorted(everything) == ids  # each run exactly once, nobody waited on a lock
    with transaction(sessions) as session:
        assert (
            leases.claim_runs(
                session=session, owner="late", lease_s=60, limit=20, statuses=["queued"]
            )
            == []
        )
        assert not leases.claim_run(session=session, run_id=ids[0], owner="late", lease_s=60)
        with status_writes():  # clean-up of the test's own rows, not a run's life
            session.query(Run).filter(Run.id.in_(ids)).update(
                {Run.status: "completed", Run.lease_owner: None}, synchronize_session=False
            )


def test_a_process_that_lost_its_lease_stops_and_writes_nothing(
    sessions: sessionmaker[Session],
    make_leased: Callable[..., RunWorker],
    postgres_url: str,
) -> None:
    worker = make_leased(test_pause="3:reason:before")
    run_id = _create(sessions, worker)
    eventually(
        lambda: _decisions(sessions, run_id) == 3 and worker.is_active(run_id),
        interval=0.05,
        what="3 decisions stored (it holds before task 3) and the run active",
    )
    # Another process took the run (as if this one had stalled past its lease).
    query(
        postgres_url,
        "UPDATE runs SET lease_owner = 'thief', "
        "lease_expires_at = now() + interval '1 hour' WHERE id = %s",
        run_id,
    )
    before = _kinds(sessions, run_id)
    worker.wait(run_id, timeout=10)  # the heartbeat noticed and the run stopped here

    run = _run(sessions, run_id)
    assert (run.status, run.lease_owner) == ("running", "thief")
    assert _kinds(sessions, run_id) == before
    assert _decisions(sessions, run_id) == 3

    # Writes are fenced too, not only the heartbeat: a late write is rolled back.
    stop = RunStop()
    recorder = SqlRecorder(
        run_id=run_id, sessions=sessions, stop=stop, fence=lease(worker).fence(run_id, stop)
    )
    record = decision_record(3)
    with pytest.raises(LeaseLost):
        recorder.save_decision(record)
    assert stop.lease_lost.is_set()
    assert _decisions(sessions, run_id) == 3


def test_cancel_reaches_the_process_running_the_run(
    sessions: sessionmaker[Session],
    make_leased: Callable[..., RunWorker],
) -> None:
    runner = make_leased(test_pause="3:reason:before")
    other = make_leased()
    run_id = _create(sessions, runner)
    eventually(lambda: _decisions(sessions, run_id) == 3, interval=0.05, what="3 decisions stored")
    assert other.is_active(run_id) and _run(sessions, run_id).status == "running"
    service.cancel_run(sessions=sessions, worker=other, run_id=run_id)
    runner.wait(run_id, timeout=10)
    run = _run(sessions, run_id)
    assert (run.status, run.lease_owner) == ("cancelled", None)
    assert _kinds(sessions, run_id)[-1] == "cancelled"


def test_a_draining_process_hands_its_runs_to_another(
    sessions: sessionmaker[Session],
    make_leased: Callable[..., RunWorker],
) -> None:
    first = make_leased(test_pause="3:reason:before")
    run_id = _create(sessions, first)
    eventually(lambda: _decisions(sessions, run_id) == 3, interval=0.05, what="3 decisions stored")
    first.close()  # SIGTERM: interrupted at a node boundary, lease released at once
    run = _run(sessions, run_id)
    assert (run.status, run.lease_owner) == ("interrupted", None)

    second = make_leased()
    assert second.recover() == [run_id]  # no waiting for a lease to expire
    second.wait(run_id, timeout=60)
    assert _run(sessions, run_id).status == "completed"
    assert _decisions(sessions, run_id) == 36
    with sessions() as session:
        resumed = [e for e in repo.events(session=session, run_id=run_id) if e.kind == "resumed"]
    assert len(resumed) == 1 and resumed[0].detail["worker"] == lease(second).owner
    assert resumed[0].detail["integrity"]["resume_at_task"] == 3
