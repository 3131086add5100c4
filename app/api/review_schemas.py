"""Bodies of the supervisor endpoints: sign-offs and (issue 12) decision reviews."""

from __future__ import annotations

from pydantic import BaseModel, Field

MAX_STATEMENT_CHARS = 4000


class SignOffRequest(BaseModel):
    statement: str = Field(
        min_length=1,
        max_length=MAX_STATEMENT_CHARS,
        description="What the supervisor states about the run, recorded with their name",
    )
