"""Template filters: how numbers and times read on the console's pages."""

from __future__ import annotations

from collections.abc import Callable
from datetime import datetime
from typing import Any

from app.store.models import as_utc


def pct(value: float | None, digits: int = 1) -> str:
    """0.8125 -> '81.3%'."""
    return "—" if value is None else f"{100 * value:.{digits}f}%"


def num(value: float | int | None, digits: int = 2) -> str:
    if value is None:
        return "—"
    if isinstance(value, int):
        return f"{value:,}"
    return f"{value:,.{digits}f}"


def when(value: datetime | None) -> str:
    return "—" if value is None else as_utc(value).strftime("%Y-%m-%d %H:%M:%S UTC")


def iso(value: datetime | None) -> str:
    return "" if value is None else as_utc(value).isoformat()


def cap(value: float | None) -> str:
    return "no cap" if value is None else f"±{value:g} tasks"


FILTERS: dict[str, Callable[..., Any]] = {
    "pct": pct,
    "num": num,
    "when": when,
    "iso": iso,
    "cap": cap,
}
