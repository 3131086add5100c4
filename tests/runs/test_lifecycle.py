"""A run's life has one owner: app.runs.lifecycle moves statuses, checked against the
transition table, and nothing else writes runs.status (enforced at run time and here, by
a scan of the source)."""

from __future__ import annotations

import ast
import itertools
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import update
from sqlalchemy.orm import Session, sessionmaker

from app.domain.lifecycle import (
    STATUS_RULES,
    TRANSITIONS,
    EventKind,
    IllegalTransitionError,
    RunStatus,
    check_transition,
)
from app.runs import lifecycle
from app.runs.lifecycle import status_writes
from app.store import repository as repo
from app.store.db import make_engine, make_session_factory, transaction
from app.store.migrate import upgrade_head
from app.store.models import Run, StatusWriteError

APP = Path(__file__).resolve().parents[2] / "app"
THE_WRITER = APP / "runs" / "lifecycle.py"
# A logging.LogRecord's `status` field (the HTTP status of an access-log line), not a run's.
NOT_A_RUN = {("observability/logs.py", "record")}


@pytest.fixture
def sessions(tmp_path: Path) -> Iterator[sessionmaker[Session]]:
    url = f"sqlite:///{tmp_path / 'ltaa.db'}"
    upgrade_head(url)
    engine = make_engine(url)
    yield make_session_factory(engine)
    engine.dispose()


def _run_in(sessions: sessionmaker[Session], status: RunStatus, run_id: str) -> None:
    with transaction(sessions) as session:
        lifecycle.new_run(
            session,
            run_id=run_id,
            created={},
            request={},
            reasoner="rules",
            mode="balanced",
            max_deviation=None,
            n_tasks=1,
            n_robots=1,
            resumes=0,
            cancel_requested=False,
        )
    if status is not RunStatus.QUEUED:
        # Set up the starting status directly, as a row restored from a backup would be.
        with transaction(sessions) as session, status_writes():
            session.execute(update(Run).where(Run.id == run_id).values(status=status.value))


def test_the_table_knows_every_status() -> None:
    assert set(STATUS_RULES) == set(RunStatus)
    for (current, target), why in TRANSITIONS.items():
        assert current is not target and why
    # Every status can be reached from queued, and every unfinished one can end.
    reachable = {RunStatus.QUEUED}
    while True:
        more = {t for (f, t) in TRANSITIONS if f in reachable} - reachable
        if not more:
            break
        reachable |= more
    assert reachable == set(RunStatus)


@pytest.mark.parametrize(
    ("current", "target"),
    [pair for pair in itertools.product(RunStatus, RunStatus) if pair[0] is not pair[1]],
    ids=lambda s: s.value,
)
def test_every_move_is_allowed_or_refused_as_the_table_says(
    sessions: sessionmaker[Session], current: RunStatus, target: RunStatus
) -> None:
    run_id = f"{current.value}-{target.value}"
    _run_in(sessions, current, run_id)
    with transaction(sessions) as session:
        run = repo.get_run(session=session, run_id=run_id)
        assert run is not None
        if (current, target) in TRANSITIONS:
            lifecycle.move(
                session, run, target, event=EventKind.INTERRUPTED, detail={"why": "test"}, error="e"
            )
        else:
            with pytest.raises(IllegalTransitionError) as err:
                lifecycle.move(session, run, target)
            assert f"cannot move from {current.value} to {target.value}" in str(err.value)
            assert "it may move to" in str(err.value)
    with sessions() as session:
        run = repo.get_run(session=session, run_id=run_id)
        assert run is not None
        kinds = [e.kind for e in repo.events(session=session, run_id=run_id)]
    if (current, target) in TRANSITIONS:
        assert (run.status, run.error, kinds) == (target.value, "e", ["created", "interrupted"])
        assert (run.finished_at is not None) == STATUS_RULES[target].finished
    else:
        assert (run.status, kinds) == (current.value, ["created"])


def test_a_conditional_move_races_to_one_winner(sessions: sessionmaker[Session]) -> None:
    _run_in(sessions, RunStatus.INTERRUPTED, "r")
    with transaction(sessions) as session:
        assert lifecycle.move_where(
            session, run_id="r", current=RunStatus.INTERRUPTED, to=RunStatus.QUEUED
        )
        assert not lifecycle.move_where(
            session, run_id="r", current=RunStatus.INTERRUPTED, to=RunStatus.QUEUED
        )
    with pytest.raises(IllegalTransitionError):
        check_transition("r", RunStatus.QUEUED, RunStatus.INTERRUPTED)


def test_writing_a_status_outside_the_lifecycle_raises(sessions: sessionmaker[Session]) -> None:
    _run_in(sessions, RunStatus.QUEUED, "r")
    with sessions() as session:
        run = repo.get_run(session=session, run_id="r")
        assert run is not None
        with pytest.raises(StatusWriteError, match=r"lifecycle\.move"):
            run.status = "running"
        with pytest.raises(StatusWriteError, match="bulk UPDATE"):
            session.execute(update(Run).where(Run.id == "r").values(status="running"))
        with pytest.raises(StatusWriteError):
            Run(id="x", status="queued")
    with sessions() as session:
        run = repo.get_run(session=session, run_id="r")
        assert run is not None and run.status == "queued"


def _status_writes_in(path: Path) -> Iterator[str]:
    """Assignments to `<x>.status`, `Run(status=...)` and `.values(status=...)` in a file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    rel = path.relative_to(APP).as_posix()
    for node in ast.walk(tree):
        targets: list[ast.expr] = []
        if isinstance(node, ast.Assign):
            for target in node.targets:
                targets.extend(target.elts if isinstance(target, ast.Tuple) else [target])
        elif isinstance(node, (ast.AugAssign, ast.AnnAssign)):
            targets.append(node.target)
        for target in targets:
            if isinstance(target, ast.Attribute) and target.attr == "status":
                owner = target.value.id if isinstance(target.value, ast.Name) else "?"
                if (rel, owner) not in NOT_A_RUN:
                    yield f"{rel}:{getattr(node, 'lineno', 0)} assigns {owner}.status"
        if isinstance(node, ast.Call):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if name in ("Run", "values") and any(k.arg == "status" for k in node.keywords):
                yield f"{rel}:{node.lineno} passes status= to {name}()"


def test_no_module_but_the_lifecycle_writes_a_status() -> None:
    found = [
        hit
        for path in sorted(APP.rglob("*.py"))
        if path != THE_WRITER
        for hit in _status_writes_in(path)
    ]
    assert found == []


def test_the_scan_finds_what_it_looks_for(tmp_path: Path) -> None:
    # The scan above must be able to fail: it flags each form of writing a status.
    assert len(list(_status_writes_in(THE_WRITER))) == 3
