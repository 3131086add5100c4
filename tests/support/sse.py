"""A minimal Server-Sent Events reader for the tests (event, id, JSON data per event)."""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any


@dataclass
class Event:
    event: str
    id: str | None
    data: Any
    retry: int | None = None


def parse_events(lines: Iterable[str]) -> Iterator[Event]:
    """Yield each event as its blank line arrives, so a reader can stop mid-stream."""
    fields: dict[str, str] = {}
    data: list[str] = []
    for line in lines:
        if line == "":
            if data:
                yield Event(
                    fields.get("event", "message"),
                    fields.get("id"),
                    json.loads("\n".join(data)),
                    int(fields["retry"]) if "retry" in fields else None,
                )
            fields, data = {}, []
        elif not line.startswith(":"):
            name, _, value = line.partition(":")
            value = value.removeprefix(" ")
            if name == "data":
                data.append(value)
            else:
                fields[name] = value
