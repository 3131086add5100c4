"""The run store's dependencies for endpoints: the app-table sessions, the run worker, and
the run id of a path."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

from fastapi import Depends, Path, Request
from sqlalchemy.orm import Session, sessionmaker

from app.runs.pages import AssignmentPages
from app.runs.schemas import RUN_ID_PATTERN
from app.runs.spec import LruCache
from app.runs.worker import RunWorker
from app.store.run_totals import Tally


@dataclass(frozen=True)
class RunsContext:
    """What the /runs routes need: the app-table sessions and the run worker."""

    sessions: sessionmaker[Session]
    worker: RunWorker
    # Polls render each stored assignment once (app.runs.pages) and fold in only the
    # decisions and attempts stored since the last (app.store.run_totals.Tally).
    pages: AssignmentPages = field(default_factory=AssignmentPages)
    tallies: LruCache[Tally] = field(default_factory=lambda: LruCache(64))


async def get_runs(request: Request) -> RunsContext:
    runs: RunsContext = request.app.state.runs
    return runs


RunsDep = Annotated[RunsContext, Depends(get_runs)]
# Checked before any query: PostgreSQL answers a NUL character in a parameter with an error.
RunIdPath = Annotated[str, Path(pattern=RUN_ID_PATTERN, description="A run id, see GET /runs")]
