"""Times in requests and answers: RFC 3339 with an offset, held in UTC."""

from __future__ import annotations

import re
from datetime import UTC, datetime
from typing import Annotated

from pydantic import AfterValidator, BeforeValidator
from pydantic_core import PydanticCustomError

from app.store.models import as_utc

# A date-time without an offset is not RFC 3339 (OpenAPI's format): a client cannot place
# it, and SQLite hands stored times back without one.
Timestamp = Annotated[datetime, AfterValidator(as_utc)]

_EXAMPLE = "e.g. 2026-12-01T09:30:00Z or 2026-12-01T09:30:00+05:00"
_DATE_TIME = r"\d{4}-\d{2}-\d{2}[Tt]\d{2}:\d{2}:\d{2}(?:\.\d+)?"
_RFC3339 = re.compile(_DATE_TIME + r"(?:[Zz]|[+-]\d{2}:\d{2})")
_NO_OFFSET = re.compile(_DATE_TIME)


def parse_rfc3339(value: object) -> datetime:
    """An RFC 3339 date-time string, offset required, in the offset it was sent in.

    Pydantic alone would take a bare number as seconds since 1970 and a time without an
    offset as it is (while the client may have meant local time)."""
    if not isinstance(value, str):
        raise PydanticCustomError(
            "datetime_type", f"must be an RFC 3339 date-time string with an offset, {_EXAMPLE}"
        )
    if _NO_OFFSET.fullmatch(value):
        raise PydanticCustomError(
            "timezone_aware",
            f"has no offset: add Z (UTC) or the site's offset such as +05:00, {_EXAMPLE}",
        )
    if not _RFC3339.fullmatch(value):
        raise PydanticCustomError(
            "datetime_parsing",
            f"must be an RFC 3339 date-time with an offset, {_EXAMPLE}",
        )
    try:
        return datetime.fromisoformat(value.upper())
    except ValueError as exc:
        raise PydanticCustomError(
            "datetime_parsing", "is not a valid date-time: {error}", {"error": str(exc)}
        ) from None


def _rfc3339_utc(value: object) -> datetime:
    """An RFC 3339 date-time string, offset required, as the same instant in UTC: SQLite
    drops an offset, so every stored time is UTC."""
    parsed = parse_rfc3339(value)
    try:
        return parsed.astimezone(UTC)
    except OverflowError:
        raise PydanticCustomError(
            "datetime_out_of_range",
            "is out of range: in UTC it falls outside the years 0001 to 9999",
        ) from None


# A time in a request: RFC 3339 with an offset (the OpenAPI date-time format), held in UTC.
RequestTime = Annotated[datetime, BeforeValidator(_rfc3339_utc)]
