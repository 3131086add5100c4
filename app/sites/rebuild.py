"""The site's outcome rows rebuilt from the record (`ltaa rebuild-estimates`): every
execution report a run recorded, as an event while it ran or an annotation after it
finished, becomes the row a report writes when it arrives (app.store.site_repository).

A revision's copies of its pinned tasks' reports are listed in its `revised` event, not
reported to it, so they count once: on the run the site reported them to.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from app.domain.annotations import AnnotationKind
from app.domain.lifecycle import EventKind
from app.store import site_repository as site_repo
from app.store.db import transaction
from app.store.models import Decision, ExecutionReport, Run, RunAnnotation, RunEvent


def _reports_of(session: Session, run: Run) -> Iterator[tuple[datetime, list[dict[str, Any]]]]:
    """(received at, updates) of every request reporting state changes to the run, in order."""
    records: list[tuple[datetime, int, dict[str, Any]]] = []
    for kind, model in (
        (EventKind.EXECUTION_REPORTED.value, RunEvent),
        (AnnotationKind.EXECUTION_REPORTED.value, RunAnnotation),
    ):
        rows = session.execute(
            select(model.created_at, model.seq, model.detail).where(
                model.run_id == run.id, model.kind == kind
            )
        )
        records.extend((created, seq, detail) for created, seq, detail in rows)
    # Events come before annotations: a run's reports become annotations once it finished.
    for created, _, detail in sorted(records, key=lambda r: (r[0], r[1])):
        yield created, list(detail.get("updates", []))


def _server_clock(update: dict[str, Any]) -> bool:
    """The update was sent without `at` (records written before the mark have none)."""
    return all(update.get(k) == v for k, v in site_repo.SERVER_CLOCK.items())


def rows_from_record(session: Session) -> list[dict[str, Any]]:
    """The outcome rows the record implies, in (run, task index) order."""
    out: list[dict[str, Any]] = []
    for run in session.scalars(select(Run).order_by(Run.id)):
        decisions = {
            d.task_index: d
            for d in session.scalars(select(Decision).where(Decision.run_id == run.id))
        }
        started = {
            r.task_index: r.started_at
            for r in session.scalars(
                select(ExecutionReport).where(ExecutionReport.run_id == run.id)
            )
        }
        for received, updates in _reports_of(session, run):
            # One record per request: the same rule as the report's (app.plans.reports).
            started_here = {
                str(u["task_id"]): not _server_clock(u) for u in updates if u["state"] == "started"
            }
            for update in updates:
                index = int(update["task_index"])
                if update["state"] not in site_repo.FINAL_STATES or index not in decisions:
                    continue
                task_id = str(update["task_id"])
                reported = site_repo.Reported(
                    task_index=index,
                    task_id=task_id,
                    state=str(update["state"]),
                    at=datetime.fromisoformat(update["at"]),
                    started_at=started.get(index),
                    together_without_at=site_repo.together_without_at(
                        started_here, task_id, at_sent=not _server_clock(update)
                    ),
                )
                out.extend(
                    site_repo.outcome_rows(
                        run=run, reported=reported, decision=decisions[index], received_at=received
                    )
                )
        session.expunge_all()  # one run's rows at a time in memory
    return sorted(out, key=_key)


def _key(row: dict[str, Any]) -> tuple[str, int, str]:
    """A row's identity: its run, task and robot (a team task has one row per member)."""
    return (row["run_id"], row["task_index"], row["robot"])


@dataclass(frozen=True)
class Comparison:
    stored: int
    rebuilt: int
    missing: list[tuple[str, int, str]]  # in the record, not in the table
    extra: list[tuple[str, int, str]]  # in the table, not in the record
    different: list[tuple[str, int, str]]

    @property
    def agree(self) -> bool:
        return not (self.missing or self.extra or self.different)


def compare(*, sessions: sessionmaker[Session]) -> Comparison:
    """The table against the record, row by row (nothing written)."""
    with sessions() as session:
        stored = {_key(r): r for r in site_repo.stored_rows(session=session)}
        rebuilt = {_key(r): r for r in rows_from_record(session)}
    return Comparison(
        stored=len(stored),
        rebuilt=len(rebuilt),
        missing=sorted(set(rebuilt) - set(stored)),
        extra=sorted(set(stored) - set(rebuilt)),
        different=sorted(k for k in set(stored) & set(rebuilt) if stored[k] != rebuilt[k]),
    )


def rebuild(*, sessions: sessionmaker[Session]) -> int:
    """Replace the table with the rows the record implies, in one transaction; how many."""
    with transaction(sessions) as session:
        rows = rows_from_record(session)
        return site_repo.replace_all(session=session, rows=rows)
