"""An answer schema read from its row (or record) with `from_attributes`, the fields whose
shape differs given beside it: the one way the endpoints build an answer from what the
store or the graph holds (issue 39: converters only where a shape really differs)."""

from __future__ import annotations

from typing import Any, TypeVar

from pydantic import BaseModel

Answer = TypeVar("Answer", bound=BaseModel)


class _Overlay:
    """`row`'s attributes, with `derived`'s names read from `derived` first."""

    __slots__ = ("_derived", "_row")

    def __init__(self, row: object, derived: dict[str, Any]) -> None:
        self._row = row
        self._derived = derived

    def __getattr__(self, name: str) -> Any:
        if name in self._derived:
            return self._derived[name]
        return getattr(self._row, name)


def from_row(schema: type[Answer], row: object, **derived: Any) -> Answer:
    """`schema` validated from `row`'s attributes; a field named in `derived` takes that
    value instead (a name resolved, a field renamed, a value computed). A field neither
    has keeps its default."""
    return schema.model_validate(_Overlay(row, derived) if derived else row, from_attributes=True)
