"""Run-level errors, shaped like domain errors so the API reports them the same way."""

from __future__ import annotations

from app.domain.errors import DomainError, NotFoundError, StateConflictError


class RunNotFoundError(NotFoundError):
    def __init__(self, run_id: str) -> None:
        super().__init__("run_id", f"no run with id '{run_id}'; list runs with GET /runs")
        self.run_id = run_id  # the API answers 410 instead when this id was archived


class RunArchivedError(DomainError):
    status_code = 410
    location = "path"

    def __init__(self, run_id: str, archive_file: str) -> None:
        super().__init__(
            "run_id",
            f"run '{run_id}' was archived to '{archive_file}' (in the server's archive "
            "directory); its record is that file, which scripts/check_trace.py verifies",
            code="archived",
        )


class RunStateConflictError(StateConflictError):
    def __init__(self, run_id: str, status: str, action: str, hint: str) -> None:
        super().__init__("run_id", f"run '{run_id}' is {status}; cannot {action}. {hint}")
