"""The canonical hashing of the audit chain: a value hashes the same before and after a round
trip through the tables, and different content never hashes alike."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sqlalchemy.orm import Session, sessionmaker

from app.audit.verify import verify_trace
from app.graph.recorder import AttemptRecord, DecisionRecord
from app.reasoners.base import ReasonerReply
from app.runs import records
from app.store import chain
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import make_engine, transaction
from app.store.migrate import upgrade_head
from tests.support.factories import run_row
from tests.support.postgres import fresh_database

DECISION = DecisionRecord(
    task_index=0,
    task_id=7,
    task_name="Lift beam",
    robot=1,
    robot_name="heavy",
    phase="early",
    expected_success=0.9,
    reasoning="strongest",
    confidence="high",
    tradeoff="none",
    quality=0.95,
    fallback=False,
    attempts=1,
    failure_log=[],
    loads_before=[0, 0, 0],
    loads_after=[0, 1, 0],
    balance_before=1.0,
    balance_after=0.5,
    severity_after="low",
    regret=0.0,
)


def _link(record: DecisionRecord, prev: str = "p", attempts: str = "a") -> str:
    values = asdict(record)
    return chain.decision_link(prev, values, attempts)


def test_representations_of_one_stored_value_hash_alike() -> None:
    base = _link(DECISION)
    # SQLite reads -0.0 back as 0.0 and NaN as NULL; numpy floats are floats; a tuple is
    # stored as a JSON list; an integer task id is stored as text.
    assert _link(replace(DECISION, regret=-0.0)) == base
    assert _link(replace(DECISION, expected_success=np.float64(0.9))) == _link(
        replace(DECISION, expected_success=0.9)
    )
    # A tuple where the record declares a list, on purpose: the stored form is the same.
    assert _link(replace(DECISION, loads_before=(0, 0, 0))) == base  # type: ignore[arg-type]
    assert _link(replace(DECISION, task_id="7")) == base
    assert _link(replace(DECISION, regret=float("nan"))) == _link(replace(DECISION, regret=None))
    assert chain.event_link(
        "p", {"seq": 1, "kind": "k", "detail": {1: (2, 3)}}
    ) == chain.event_link("p", {"seq": 1, "kind": "k", "detail": {"1": [2, 3]}})


@pytest.mark.parametrize(
    "change",
    [
        {"robot": 2},
        {"robot_name": "light"},
        {"expected_success": 0.9000000000000001},
        {"reasoning": "strongest "},
        {"fallback": True},
        {"failure_log": ["x"]},
        {"loads_after": [1, 0, 0]},
        {"regret": None},
        {"task_index": 1},
        {"severity_after": "high"},
    ],
)
def test_any_change_of_content_changes_the_link(change: dict[str, Any]) -> None:
    assert _link(replace(DECISION, **change)) != _link(DECISION)


def test_a_link_depends_on_its_predecessor_its_attempts_its_run_and_its_table() -> None:
    assert _link(DECISION, prev="q") != _link(DECISION)
    assert _link(DECISION, attempts="b") != _link(DECISION)
    assert chain.genesis("decisions", "run-a") != chain.genesis("decisions", "run-b")
    assert chain.genesis("decisions", "run-a") != chain.genesis("events", "run-a")
    attempt = {name: None for name in chain.ATTEMPT_FIELDS} | {
        "attempt": 1,
        "tier": 0,
        "system_prompt": "s",
        "user_prompt": "u",
        "input_tokens": 0,
        "output_tokens": 0,
        "latency_ms": 1.5,
        "transport_retries": 0,
        "reply_extra": {},
        "scores": {},
    }
    assert chain.attempts_digest([attempt]) != chain.attempts_digest(
        [attempt | {"feedback": "try again"}]
    )
    assert chain.attempts_digest([]) != chain.attempts_digest([attempt])


@pytest.fixture(params=["sqlite", "postgresql"])
def sessions(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[sessionmaker[Session]]:
    """Both back-ends: each stores floats and JSON its own way."""
    with ExitStack() as stack:
        url = (
            f"sqlite:///{tmp_path / 'ltaa.db'}"
            if request.param == "sqlite"
            else stack.enter_context(fresh_database())
        )
        upgrade_head(url)  # the real schema, through the real migrations
        engine = make_engine(url)
        stack.callback(engine.dispose)
        yield sessionmaker(engine, expire_on_commit=False)


def test_awkward_values_verify_after_a_round_trip_through_the_tables(
    sessions: sessionmaker[Session],
) -> None:
    """Hashes are computed from the values written and checked against the values read."""
    with transaction(sessions) as session:
        session.add(run_row("r1", "completed", mode="m", max_deviation=None, n_tasks=3, n_robots=3))
        session.flush()
        repo.add_event(
            session=session,
            run_id="r1",
            kind="created",
            # An int key and a tuple on purpose: JSON turns them into "4" and a list.
            detail={"tasks": 3, 4: (1, 2), "share": -0.0, "max_deviation": None},  # type: ignore[dict-item]
        )
    for t in range(3):
        with transaction(sessions) as session:
            reply = ReasonerReply(
                text="**Decision**: heavy ✓",
                input_tokens=10,
                output_tokens=5,
                latency_ms=np.float64(12.25),
                model="m",
                transport_retries=0,
                extra={"stop_reason": "end_turn"},
            )
            decision_repo.upsert_attempt(
                session=session,
                run_id="r1",
                values=records.attempt_values(
                    AttemptRecord(
                        task_index=t,
                        attempt=1,
                        tier=0,
                        system_prompt="sys",
                        user_prompt=f"task {t}",
                        reply=reply,
                        parsed={"robot": "heavy", "confidence": 0.5},
                        scores={"explanation": 1.0},
                        quality=np.float64(1 / 3),
                        accepted=True,
                    )
                ),
            )
            decision_repo.upsert_decision(
                session=session,
                run_id="r1",
                values=records.decision_values(
                    replace(
                        DECISION,
                        task_index=t,
                        regret=-0.0 if t else None,
                        expected_success=np.float64(0.1 + 0.2),
                        # A tuple on purpose: the hash must survive its becoming a JSON list.
                        loads_before=(t, 0, 0),  # type: ignore[arg-type]
                    )
                ),
            )
    with transaction(sessions) as session:
        repo.add_event(session=session, run_id="r1", kind="completed", detail={"decisions": 3})

    report = verify_trace(sessions=sessions, run_id="r1")
    assert report.ok, report.first_break
    assert (report.decisions.rows, report.events.rows, report.decisions.unchained) == (3, 2, 0)
