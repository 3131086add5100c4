"""The answer bodies of app.schedules that are its own (a run's schedule answers
app.allocation's ScheduleOut, the shape POST /allocate answers too)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field


class ImportedDraft(BaseModel):
    """A draft instance: `tasks`, `robots`, `start` as a request sends them, plus what was
    read and what was not (docs/exchange.md)."""

    tasks: list[dict[str, Any]] = Field(description="Tasks in the shape a request sends")
    robots: list[dict[str, Any]] = Field(description="The assigned resources, rates empty")
    start: str | None = Field(description="The project's start (RFC 3339)")
    source: dict[str, Any] = Field(
        description="format, project, calendar, features_field, counts read and imported, "
        "and the calendar caveat"
    )
    skipped: list[dict[str, Any]] = Field(description="Each item not imported, with why")
