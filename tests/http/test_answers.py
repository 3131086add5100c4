"""app.http.answers.from_row: an answer read from a row's attributes, the derived fields
first, a field neither names at its default."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from pydantic import BaseModel, ValidationError

from app.http.answers import from_row


@dataclass
class Row:
    id: str
    robot: int
    note: str | None = None


class Answer(BaseModel):
    id: str
    robot: str
    note: str | None
    extra: int = 7


def test_the_row_s_attributes_with_the_derived_fields_first() -> None:
    answer = from_row(Answer, Row("a", 0, "n"), robot="crane")
    assert answer == Answer(id="a", robot="crane", note="n", extra=7)
    assert from_row(Answer, Row("a", 0), robot="crane", note="given").note == "given"


def test_a_field_neither_holds_is_its_default_and_a_missing_required_one_refused() -> None:
    assert from_row(Answer, Row("a", 0), robot="crane").extra == 7
    with pytest.raises(ValidationError):
        from_row(Answer, Row("a", 0))  # robot is the row's int index: its name must be given
