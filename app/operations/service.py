"""What the /admin endpoints and `ltaa archive` call: a backup into the backup directory,
and an archive of finished lineages that gives the embedded store's pages back after."""

from __future__ import annotations

from collections.abc import Callable
from datetime import datetime
from pathlib import Path

from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.operations import archive, backup
from app.runs.factory import uses_leases


class OutsideBackupDirError(ValueError):
    """A backup's `dest` is not a directory inside LTAA_BACKUP_DIR."""


def backup_into_backup_dir(*, settings: Settings, dest: str) -> backup.BackupReport:
    """A backup into `dest`, which must be a directory inside the backup root (a server
    writes only there: the path comes from a request). Raises OutsideBackupDirError, and
    whatever backup.backup raises."""
    root = settings.backup_root.resolve()
    path = Path(dest).resolve()
    if path == root or root not in path.parents:
        raise OutsideBackupDirError(f"dest must be a directory inside {root} (LTAA_BACKUP_DIR)")
    return backup.backup(settings=settings, dest=path)


def archive_finished(
    *,
    sessions: sessionmaker[Session],
    settings: Settings,
    before: datetime,
    after_file: Callable[[str], None] | None = None,
) -> list[archive.ArchivedLineage]:
    """Every lineage finished before `before` archived into the archive root
    (app.operations.archive.archive); then, if any was, the embedded SQLite store vacuumed
    to give the deleted rows' pages back (PostgreSQL reclaims its own)."""
    done = archive.archive(
        sessions=sessions, before=before, dest=settings.archive_root, after_file=after_file
    )
    if done and not uses_leases(settings.db_url):
        archive.vacuum(backup.database_file(settings))
    return done
