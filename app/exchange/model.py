"""What a reader takes out of a file, before any of it becomes a draft.

Both readers (MSPDI and XER) fill the same `ReadProject`; `app.exchange.draft` turns it
into a draft instance, so the rules (milestones bridged, features, skipped items, cycles)
are written once and the two formats cannot drift apart.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from typing import Any, Literal

LinkType = Literal["FS", "SS", "FF", "SF"]
LINK_TYPES: tuple[LinkType, ...] = ("FS", "SS", "FF", "SF")


@dataclass
class Activity:
    id: str  # the file's task id: P6 task_code, MS Project UID
    key: str  # the file's internal key links and assignments use (P6 task_id, MS UID)
    name: str
    duration: float | None  # working minutes; None: the file gives none
    summary: bool = False  # a summary task or WBS level, not work
    summary_why: str = "a summary task or WBS level: structure, not work"
    milestone: bool = False
    features: str | None = None  # the features field's raw text
    resources: list[str] = field(default_factory=list)  # assigned resource names
    release: datetime | None = None
    deadline: datetime | None = None
    notes: list[tuple[str, str]] = field(default_factory=list)  # (kind, why) not imported


@dataclass(frozen=True)
class Link:
    predecessor: str  # Activity.key
    successor: str  # Activity.key
    type: LinkType
    lag: float  # minutes; negative: a lead
    # Set when the link cannot be imported as it stands (a cross-project link, a
    # percentage lag): the reason, and the link is listed in `skipped`.
    refused: str | None = None


@dataclass
class ReadProject:
    format: Literal["mspdi", "xer"]
    name: str | None
    start: datetime | None
    calendar: str | None
    activities: list[Activity]
    links: list[Link]
    resources: int  # resources the file defines
    assignments: int  # (task, resource) assignments read
    features_field: str | None  # the field the features were read from, as the file names it


@dataclass
class Draft:
    """A draft instance: `tasks`, `robots` and `start` in exactly the shape a run or
    /allocate request sends, `source` (what was read) and `skipped` (each item not
    imported, with why)."""

    tasks: list[dict[str, Any]]
    robots: list[dict[str, Any]]
    start: str | None
    source: dict[str, Any]
    skipped: list[dict[str, Any]]

    def request(self) -> dict[str, Any]:
        """The part a request sends."""
        out: dict[str, Any] = {"tasks": self.tasks, "robots": self.robots}
        if self.start is not None:
            out["start"] = self.start
        return out

    def to_dict(self) -> dict[str, Any]:
        return {**self.request(), "source": self.source, "skipped": self.skipped}
