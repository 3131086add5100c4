"""Backup and restore of the embedded (SQLite) store: both files, consistent with each
other, taken while runs execute.

`backup` holds every run of this process at a node boundary (app.graph.gate), copies the
app database and the checkpoint file with SQLite's online backup API (a consistent copy
of each, whatever other connections do) and lets the runs go on. The copy is what a
kill -9 at that moment would have left: restored and started, the server resumes each
running run from there through the usual integrity check.

PostgreSQL is backed up with its own tools (pg_dump; see docs/operations.md).
"""

from __future__ import annotations

import json
import sqlite3
import time
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path

from sqlalchemy.engine import make_url

from app.config import Settings
from app.graph.gate import NODE_GATE
from app.graph.version import current_version

DATABASE = "ltaa.db"
CHECKPOINTS = "checkpoints.sqlite"
MANIFEST = "manifest.json"


class BackupError(RuntimeError):
    """The backup or restore cannot be made as asked; the message says what to change."""


@dataclass(frozen=True)
class BackupReport:
    dest: str
    created_at: str
    graph_version: str
    held_ms: float  # how long runs were held at their node boundary
    waited_for_nodes: int  # node bodies the hold let finish first
    files: dict[str, int]  # name -> bytes
    runs: dict[str, int]  # run id -> decisions stored, for runs not finished


def database_file(settings: Settings) -> Path:
    url = make_url(settings.db_url)
    if url.get_backend_name() != "sqlite" or not url.database:
        raise BackupError(
            "ltaa backup copies the embedded SQLite store; this server uses "
            f"{url.get_backend_name()}: back it up with pg_dump (docs/operations.md)"
        )
    return Path(url.database)


def _copy(source: Path, target: Path) -> None:
    src = sqlite3.connect(source)
    dst = sqlite3.connect(target)
    try:
        src.backup(dst)
    finally:
        dst.close()
        src.close()


def _empty_dir(dest: Path, what: str) -> None:
    if dest.exists() and (not dest.is_dir() or any(dest.iterdir())):
        raise BackupError(f"{what} {dest} must be a new or empty directory")
    dest.mkdir(parents=True, exist_ok=True)


def _open_runs(path: Path) -> dict[str, int]:
    conn = sqlite3.connect(path)
    try:
        rows = conn.execute(
            "SELECT runs.id, count(decisions.id) FROM runs LEFT JOIN decisions "
            "ON decisions.run_id = runs.id WHERE runs.status NOT IN "
            "('completed', 'cancelled') GROUP BY runs.id"
        ).fetchall()
    finally:
        conn.close()
    return {str(run_id): int(n) for run_id, n in rows}


def backup(*, settings: Settings, dest: Path) -> BackupReport:
    """Copy both files of the store into dest (new or empty), runs held meanwhile."""
    db = database_file(settings)
    checkpoints = Path(settings.checkpoint_file)
    if not db.is_file():
        raise BackupError(f"no store to back up: {db} does not exist")
    dest = dest.resolve()
    _empty_dir(dest, "the backup destination")
    with NODE_GATE.held() as waited_for:
        held_from = time.perf_counter()
        _copy(db, dest / DATABASE)
        if checkpoints.is_file():
            _copy(checkpoints, dest / CHECKPOINTS)
        held_ms = (time.perf_counter() - held_from) * 1000
    report = BackupReport(
        dest=str(dest),
        created_at=datetime.now(UTC).isoformat(),
        graph_version=current_version(settings.test_graph_version),
        held_ms=round(held_ms, 1),
        waited_for_nodes=waited_for,
        files={p.name: p.stat().st_size for p in sorted(dest.iterdir())},
        runs=_open_runs(dest / DATABASE),
    )
    (dest / MANIFEST).write_text(json.dumps(asdict(report), indent=2) + "\n", encoding="utf-8")
    return report


def restore(*, settings: Settings, source: Path) -> list[str]:
    """Fill an empty data directory from a backup; returns the files written. Refuses a
    directory that already holds a store (restore never overwrites one)."""
    source = source.resolve()
    if not (source / MANIFEST).is_file() or not (source / DATABASE).is_file():
        raise BackupError(f"{source} is not an ltaa backup (no {MANIFEST} and {DATABASE})")
    db = database_file(settings)
    checkpoints = Path(settings.checkpoint_file)
    present = [str(p) for p in (db, checkpoints) if p.exists()]
    if present:
        raise BackupError(
            f"the data directory already holds a store ({', '.join(present)}); restore "
            "into an empty data directory (LTAA_DATA_DIR) and point the server at it"
        )
    db.parent.mkdir(parents=True, exist_ok=True)
    checkpoints.parent.mkdir(parents=True, exist_ok=True)
    written = []
    for name, target in ((DATABASE, db), (CHECKPOINTS, checkpoints)):
        if (source / name).is_file():
            _copy(source / name, target)
            written.append(str(target))
    return written
