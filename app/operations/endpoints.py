"""Supervisor operations on the store itself, while the server runs: backup, archive."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict, Field

from app.graph.gate import GateTimeoutError
from app.http.deps import SettingsDep, SupervisorDep
from app.http.errors import ApiError
from app.http.responses import BODY, SUPERVISOR, errors
from app.http.times import RequestTime
from app.operations import backup, service
from app.runs.deps import RunsDep

router = APIRouter(prefix="/admin", tags=["admin"])


class BackupRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")

    dest: str = Field(
        min_length=1,
        max_length=4096,
        pattern=r"^/[^\x00]*$",
        description="Absolute path, on the server's machine, of a new or empty directory "
        "inside LTAA_BACKUP_DIR (default: the data directory's backups/)",
    )


class BackupOut(BaseModel):
    dest: str
    created_at: str
    graph_version: str
    held_ms: float = Field(description="How long runs were held at their node boundary")
    waited_for_nodes: int = Field(description="Node bodies the hold let finish first")
    files: dict[str, int] = Field(description="File name -> bytes")
    runs: dict[str, int] = Field(
        description="Runs not finished in the backup -> their decisions stored: where each "
        "resumes once the backup is restored"
    )


@router.post("/backup", response_model=BackupOut, responses=errors(*SUPERVISOR, *BODY, 409, 503))
def backup_store(caller: SupervisorDep, body: BackupRequest, settings: SettingsDep) -> BackupOut:
    """For supervisors (`ltaa backup DEST` calls this while a server holds the store): copy
    both SQLite files consistently, runs held at a node boundary meanwhile."""
    try:
        report = service.backup_into_backup_dir(settings=settings, dest=body.dest)
    except service.OutsideBackupDirError as exc:
        raise ApiError(422, ["body", "dest"], str(exc), "outside_backup_dir") from None
    except backup.BackupError as exc:
        raise ApiError(409, ["body", "dest"], str(exc), "backup_refused") from None
    except OSError as exc:
        raise ApiError(
            422, ["body", "dest"], f"cannot write there: {exc.strerror}", "os_error"
        ) from None
    except GateTimeoutError as exc:
        raise ApiError(
            503,
            ["body", "dest"],
            f"runs did not reach a node boundary: {exc}; retry",
            "backup_busy",
        ) from None
    return BackupOut(**report.__dict__)


class ArchiveRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")

    before: RequestTime = Field(
        description="Archive lineages whose head is completed or cancelled and finished "
        "before this time (RFC 3339, with an offset: Z or +05:00)"
    )


class ArchivedLineageOut(BaseModel):
    head: str
    runs: list[str]
    files: list[str]


class ArchiveOut(BaseModel):
    archive_dir: str
    lineages: list[ArchivedLineageOut]


@router.post("/archive", response_model=ArchiveOut, responses=errors(*SUPERVISOR, *BODY))
def archive_runs(
    caller: SupervisorDep, body: ArchiveRequest, settings: SettingsDep, runs: RunsDep
) -> ArchiveOut:
    """For supervisors (`ltaa archive` calls this while a server holds the store): write
    each selected run's verified export to the archive directory, delete its rows, leave a
    tombstone (lookups then answer 410 naming the file), then vacuum."""
    done = service.archive_finished(sessions=runs.sessions, settings=settings, before=body.before)
    return ArchiveOut(
        archive_dir=str(settings.archive_root),
        lineages=[ArchivedLineageOut(head=x.head, runs=x.runs, files=x.files) for x in done],
    )
