"""A poll's totals aggregated in SQL (app.store.run_totals) equal the row-by-row ones they
replaced: workload, regret (None when any decision has none) and LLM usage."""

from __future__ import annotations

from pathlib import Path

from app.reasoners.base import ReasonerReply
from app.runs import records
from app.runs.lifecycle import RunStatus
from app.runs.recorder import RunStop, SqlRecorder
from app.store import decision_repository as decision_repo
from app.store import run_totals
from app.store.db import make_engine, make_session_factory, transaction
from app.store.migrate import upgrade_head
from tests.store.test_fenced_writes import _attempt
from tests.support.factories import decision_record, run_row


def test_sql_totals_equal_the_row_by_row_ones(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'app.db'}"
    upgrade_head(url)
    sessions = make_session_factory(make_engine(url))
    with transaction(sessions) as session:
        session.add(run_row("r1", RunStatus.RUNNING.value, n_tasks=6))
    recorder = SqlRecorder(run_id="r1", sessions=sessions, stop=RunStop())
    for t in range(6):
        attempt = _attempt(t)
        model = None if t % 3 == 0 else f"model-{t % 2}"  # the rules reasoner names none
        attempt.reply = ReasonerReply(
            text="x", input_tokens=10 * t, output_tokens=t, latency_ms=0.5 * t, model=model
        )
        recorder.save_attempt(attempt)
        recorder.save_decision(decision_record(t, robot=t % 2, regret=0.01 * t))

    with sessions() as session:
        totals = run_totals.decision_totals(session=session, run_id="r1")
        outcomes = decision_repo.decision_outcomes(session=session, run_id="r1")
        by_rows = records.usage_of(decision_repo.reply_costs(session=session, run_id="r1"))
        by_sums = records.usage_of_totals(run_totals.reply_totals(session=session, run_id="r1"))
        page = run_totals.decision_page(session=session, run_id="r1", offset=2, limit=3)
    assert totals.allocated == len(outcomes) == 6
    assert totals.by_robot == {0: 3, 1: 3}
    assert totals.regret is not None
    assert abs(totals.regret - sum(o.regret for o in outcomes)) < 1e-12
    assert by_sums.llm_calls == by_rows.llm_calls == 4
    assert (by_sums.input_tokens, by_sums.output_tokens) == (
        by_rows.input_tokens,
        by_rows.output_tokens,
    )
    assert abs(by_sums.latency_ms - by_rows.latency_ms) < 1e-9
    assert [records.decision_record(d).task_index for d in page] == [2, 3, 4]
    # A poll that kept some of the page reads its indexes, then the rows it lacks.
    with sessions() as session:
        indexes = run_totals.page_indexes(session=session, run_id="r1", offset=2, limit=3)
        rows = run_totals.decision_rows(session=session, run_id="r1", tasks=[2, 4])
        none = run_totals.decision_rows(session=session, run_id="r1", tasks=[])
        everything = run_totals.page_indexes(session=session, run_id="r1", offset=0, limit=None)
    assert indexes == [d.task_index for d in page] and everything == list(range(6))
    assert rows == [page[0], page[2]] and none == []

    recorder.save_decision(decision_record(5, robot=1, regret=None))
    with sessions() as session:
        assert run_totals.decision_totals(session=session, run_id="r1").regret is None


def test_a_tally_folded_poll_by_poll_equals_the_sql_totals(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'app.db'}"
    upgrade_head(url)
    sessions = make_session_factory(make_engine(url))
    with transaction(sessions) as session:
        session.add(run_row("r1", RunStatus.RUNNING.value, n_tasks=9))
    recorder = SqlRecorder(run_id="r1", sessions=sessions, stop=RunStop())
    settled = run_totals.Tally()

    def poll() -> None:
        nonlocal settled
        with sessions() as session:
            now, settled = run_totals.tally(session=session, run_id="r1", settled=settled)
            totals = run_totals.decision_totals(session=session, run_id="r1")
            replies = run_totals.reply_totals(session=session, run_id="r1")
        assert (now.totals().allocated, now.totals().by_robot) == (
            totals.allocated,
            totals.by_robot,
        )
        assert (now.totals().regret is None) == (totals.regret is None)
        if totals.regret is not None:
            assert abs((now.totals().regret or 0.0) - totals.regret) < 1e-12
        assert records.usage_of_totals(now.reply_rows()) == records.usage_of_totals(replies)

    # Pins past a gap (a revision's scattered pins) are stored first: counted, not settled.
    for t in (6, 8):
        recorder.save_decision(decision_record(t, robot=1, regret=0.0))
    poll()
    assert settled.through == -1
    for t in range(6):
        prompt = _attempt(t)
        prompt.reply = None
        recorder.save_attempt(prompt)
        poll()  # the task being decided: its prompt, then its reply, are read again
        prompt.reply = ReasonerReply(text="x", input_tokens=t, output_tokens=1, model="m")
        recorder.save_attempt(prompt)
        poll()
        recorder.save_decision(decision_record(t, robot=t % 2, regret=0.01 * t))
        poll()
        assert settled.through == (6 if t == 5 else t)  # the pin at 6 joins the prefix
    recorder.save_decision(decision_record(7, robot=0, regret=None))
    poll()
    assert settled.through == 8 and settled.allocated == 9 and settled.totals().regret is None
