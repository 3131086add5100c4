"""Archive old runs: whole lineages whose head is terminal and older than a date become
verified JSON-lines files, their rows deleted, a tombstone left behind.

Per lineage, in this order, so a kill -9 at any point leaves each run either archived and
deleted or intact:
1. each run's export (app.audit.export.trace_record, the format scripts/check_trace.py
   verifies) with a last `verify` line (the chain check and heads) goes to a temporary
   file, fsynced, then renamed into place: a file is whole or absent;
2. one transaction deletes the lineage's rows (events, decisions, attempts and signatures
   by cascade) and inserts a tombstone per run (id, heads, archive file). A crash before
   the commit leaves the rows (and at most an archive file that the next archive rewrites).

A lineage is a run and its revisions. Until revisions exist every run is its own lineage;
`lineage_of` follows a `revision_of` / `superseded_by` link as soon as runs carry one.
"""

from __future__ import annotations

import json
import logging
import os
import sqlite3
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from app.audit.export import trace_record
from app.audit.verify import verify_trace
from app.domain.lifecycle import RunStatus
from app.store import repository as repo
from app.store.db import transaction
from app.store.models import ArchivedRun, Run, RunAnnotation, as_utc

log = logging.getLogger("ltaa.archive")

# A lineage may be archived only when its head can never change again.
TERMINAL = (RunStatus.COMPLETED, RunStatus.CANCELLED)


@dataclass(frozen=True)
class ArchivedLineage:
    head: str
    runs: list[str]
    files: list[str]


def lineage_of(session: Session, run: Run) -> list[Run]:
    """The run and its revisions, oldest first, following whichever link runs carry."""
    lineage = [run]
    seen = {run.id}
    current = run
    while (older := getattr(current, "revision_of", None)) and older not in seen:
        found = session.get(Run, older)
        if found is None:
            break
        lineage.insert(0, found)
        seen.add(found.id)
        current = found
    current = run
    while (newer := getattr(current, "superseded_by", None)) and newer not in seen:
        found = session.get(Run, newer)
        if found is None:
            break
        lineage.append(found)
        seen.add(found.id)
        current = found
    return lineage


def _write_atomically(path: Path, lines: list[str]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", encoding="utf-8") as out:
        out.writelines(lines)
        out.flush()
        os.fsync(out.fileno())
    os.replace(tmp, path)
    directory = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(directory)
    finally:
        os.close(directory)


def _export_lines(
    sessions: sessionmaker[Session], run_id: str
) -> tuple[list[str], dict[str, object]]:
    report = verify_trace(sessions=sessions, run_id=run_id)
    lines = [
        json.dumps(line, ensure_ascii=False) + "\n"
        for page in trace_record(sessions=sessions, run_id=run_id)
        for line in page
    ]
    heads = {"decisions": report.decisions.head, "events": report.events.head}
    verified = {
        "type": "verify",
        "ok": report.ok,
        "chain_scheme": report.chain_scheme,
        "heads": heads,
        "broken": None if report.first_break is None else report.first_break.reason,
    }
    # After the `end` line: scripts/check_trace.py reads the record up to `end`.
    lines.append(json.dumps(verified) + "\n")
    return lines, {"heads": heads, "ok": report.ok}


def _state(session: Session, run_id: str) -> tuple[str | None, str | None, int]:
    """What may still change about a finished run: its status (a failed run resumed), the
    revision that replaced it, and how many annotations it has."""
    run = session.get(Run, run_id)
    if run is None:
        return None, None, 0
    count = session.scalar(
        select(func.count()).select_from(RunAnnotation).where(RunAnnotation.run_id == run_id)
    )
    return run.status, run.superseded_by, int(count or 0)


def candidates(*, sessions: sessionmaker[Session], before: datetime) -> list[list[str]]:
    """Lineages (run ids, oldest first) whose head is terminal and finished before `before`."""
    cutoff = as_utc(before)
    chosen: list[list[str]] = []
    taken: set[str] = set()
    with sessions() as session:
        for run in session.scalars(select(Run).order_by(Run.created_at)):
            if run.id in taken:
                continue
            lineage = lineage_of(session, run)
            head = lineage[-1]
            taken.update(r.id for r in lineage)
            if head.status not in TERMINAL or head.finished_at is None:
                continue
            if as_utc(head.finished_at) >= cutoff:
                continue
            chosen.append([r.id for r in lineage])
    return chosen


def archive(
    *,
    sessions: sessionmaker[Session],
    before: datetime,
    dest: Path,
    after_file: Callable[[str], None] | None = None,
) -> list[ArchivedLineage]:
    """Archive every lineage `candidates` selects into dest (created if needed).
    `after_file(run_id)`: a test seam called after a run's file is in place."""
    dest.mkdir(parents=True, exist_ok=True)
    done = []
    for lineage in candidates(sessions=sessions, before=before):
        files, tombstones = [], []
        with sessions() as session:
            exported = {run_id: _state(session, run_id) for run_id in lineage}
        for run_id in lineage:
            lines, summary = _export_lines(sessions, run_id)
            path = dest / f"run-{run_id}.jsonl"
            _write_atomically(path, lines)
            if after_file is not None:
                after_file(run_id)
            files.append(str(path))
            tombstones.append((run_id, summary))
        with transaction(sessions) as session:
            # Under the write lock: a lineage revised, signed off or reported on while its
            # files were written would lose that from the archive; it stays, for next time.
            repo.get_run(session=session, run_id=lineage[-1], for_update=True)
            now = {run_id: _state(session, run_id) for run_id in lineage}
            if now != exported:
                log.warning(
                    "lineage %s changed while it was being archived; left in place", lineage
                )
                for path_text in files:
                    Path(path_text).unlink(missing_ok=True)
                continue
            for (run_id, summary), path_text in zip(tombstones, files, strict=True):
                run = session.get(Run, run_id)
                if run is None:
                    continue
                session.add(
                    ArchivedRun(
                        id=run_id,
                        lineage_head=lineage[-1],
                        archive_file=Path(path_text).name,
                        heads=summary["heads"],
                        verified=bool(summary["ok"]),
                        status=run.status,
                    )
                )
                session.delete(run)
        done.append(ArchivedLineage(head=lineage[-1], runs=lineage, files=files))
    return done


def vacuum(database_file: Path) -> None:
    """Give the archived rows' pages back to the disk."""
    conn = sqlite3.connect(database_file, timeout=60)
    try:
        conn.execute("VACUUM")
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    finally:
        conn.close()
