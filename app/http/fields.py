"""Field types that every feature's request bodies share: names, and text that PostgreSQL
can store (no NUL character)."""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator, Field, StrictStr, StringConstraints
from pydantic_core import PydanticCustomError

from app.domain.models import MAX_NAME_CHARS


def no_nul(value: str) -> str:
    # PostgreSQL refuses a NUL in any text value, so a run naming one would be accepted and
    # then fail when its first decision is stored; refuse it up front on every back-end.
    if "\x00" in value:
        raise PydanticCustomError(
            "nul_character", "must not contain a NUL character (\\u0000); remove it"
        )
    return value


NoNul = AfterValidator(no_nul)
Name = Annotated[StrictStr, Field(min_length=1, max_length=MAX_NAME_CHARS), NoNul]

SiteName = Annotated[
    str, StringConstraints(min_length=1, max_length=MAX_NAME_CHARS, pattern=r"^[^\x00]+$")
]
