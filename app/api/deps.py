"""`Annotated` dependency aliases that routes take as parameters."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Request
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.runs.worker import RunWorker


def get_app_settings(request: Request) -> Settings:
    # The instance create_app() was given, not a fresh read of the environment.
    settings: Settings = request.app.state.settings
    return settings


SettingsDep = Annotated[Settings, Depends(get_app_settings)]


@dataclass(frozen=True)
class RunsContext:
    """What the /runs routes need: the app-table sessions and the run worker."""

    sessions: sessionmaker[Session]
    worker: RunWorker


def get_runs(request: Request) -> RunsContext:
    runs: RunsContext = request.app.state.runs
    return runs


RunsDep = Annotated[RunsContext, Depends(get_runs)]
