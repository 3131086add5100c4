"""One usage rule: replies that name a model count; the graph, the store and the API agree."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.domain.usage import ReplyUsage, Usage
from app.graph.recorder import AttemptRecord
from app.graph.usage import usage_from_attempts
from app.reasoners.base import ReasonerReply
from app.runs import records as row_records
from app.store import decision_repository as decision_repo
from app.store.db import make_engine, make_session_factory, transaction
from app.store.migrate import upgrade_head
from tests.support.factories import run_row

REPLIES = [
    ReasonerReply("a", 100, 40, latency_ms=12.5, model="claude-x", transport_retries=2),
    ReasonerReply("rules", 0, 0, latency_ms=0.1),  # the rules reasoner: no model, not a call
    ReasonerReply("b", 70, 30, latency_ms=7.5, model="claude-x"),
    ReasonerReply("", 9, 9, latency_ms=3.0, extra={"error": "HTTP 529"}),  # transport gave up
]
EXPECTED = Usage(
    llm_calls=2, input_tokens=170, output_tokens=70, transport_retries=2, latency_ms=20.0
)


def records() -> list[AttemptRecord]:
    out = [
        AttemptRecord(task_index=i, attempt=1, tier=0, system_prompt="s", user_prompt="u", reply=r)
        for i, r in enumerate(REPLIES)
    ]
    out.append(AttemptRecord(task_index=9, attempt=1, tier=0, system_prompt="s", user_prompt="u"))
    return out


def test_from_replies_counts_only_replies_that_name_a_model() -> None:
    replies = [
        ReplyUsage(r.model, r.input_tokens, r.output_tokens, r.transport_retries, r.latency_ms)
        for r in REPLIES
    ]
    assert Usage.from_replies(replies) == EXPECTED
    assert Usage.from_replies([]) == Usage()
    assert Usage.from_replies([ReplyUsage(None, 5, 5, 1, 1.0)]) == Usage()


def test_recorded_attempts_and_stored_rows_count_alike(tmp_path: Path) -> None:
    assert usage_from_attempts(records()) == EXPECTED
    url = f"sqlite:///{tmp_path / 'ltaa.db'}"
    upgrade_head(url)
    engine = make_engine(url)
    try:
        sessions = make_session_factory(engine)
        run = run_row("r1", "running", reasoner="anthropic", n_tasks=10, n_robots=3)
        with transaction(sessions) as session:
            session.add(run)
            session.flush()  # the attempts' foreign key needs the run row first
            for record in records():
                decision_repo.upsert_attempt(
                    session=session, run_id="r1", values=row_records.attempt_values(record)
                )
        with sessions() as session:
            stored = row_records.usage_of(decision_repo.attempts(session=session, run_id="r1"))
            costs = row_records.usage_of(decision_repo.reply_costs(session=session, run_id="r1"))
            spent = decision_repo.tokens_spent(session=session, run_id="r1")
    finally:
        engine.dispose()
    assert stored == EXPECTED
    assert costs == EXPECTED
    assert stored.latency_ms == pytest.approx(20.0)
    assert spent == EXPECTED.input_tokens + EXPECTED.output_tokens
