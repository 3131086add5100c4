"""Task ids and `after` entries of a request: plain ids and typed links
(docs/schedules.md#links), for the task schemas of /allocate, /runs and revisions."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, PlainSerializer, PlainValidator
from pydantic_core import PydanticCustomError

from app.domain.links import MAX_LAG, Link
from app.domain.models import MAX_NAME_CHARS
from app.http.fields import no_nul

_JSON_TYPES = {
    bool: "a boolean",
    float: "a number",
    list: "an array",
    dict: "an object",
    type(None): "null",
}


def _task_id(value: object) -> int | str:
    # One error naming the field, rather than one per member of an int | str union.
    if isinstance(value, int | str) and not isinstance(value, bool) and str(value).strip():
        if len(str(value)) > MAX_NAME_CHARS:
            raise PydanticCustomError(
                "task_id_too_long",
                "task id must be at most {limit} characters, got {got}",
                {"limit": MAX_NAME_CHARS, "got": len(str(value))},
            )
        if isinstance(value, str):
            no_nul(value)
        return value
    raise PydanticCustomError(
        "task_id_type",
        "task id must be an integer or a non-empty string, not {got}",
        {"got": _JSON_TYPES.get(type(value), "an empty string")},
    )


TaskId = Annotated[
    int | str,
    PlainValidator(_task_id, json_schema_input_type=int | str),
    Field(description="Integer or string, unique in the queue"),
]


class LinkIn(BaseModel):
    """A typed link (docs/schedules.md#links): this task's start (FS, SS) or end (FF, SF)
    comes at least `lag` minutes after the predecessor's end (FS, FF) or start (SS, SF)."""

    model_config = ConfigDict(extra="forbid")

    task: TaskId
    type: Literal["FS", "SS", "FF", "SF"] = Field("FS", description="Default FS")
    lag: float = Field(
        0, ge=-MAX_LAG, le=MAX_LAG, description="Minutes; negative for a lead. Default 0"
    )


def _after_entry(value: object) -> int | str | Link:
    # The link's type and lag are checked by the domain with the rest of the links
    # (app/domain/links.py), so a bad one is named `tasks.4.after.1.type` wherever an
    # instance comes from (a request, a stored run, the console's draft).
    if isinstance(value, dict):
        extra = sorted(set(value) - {"task", "type", "lag"})
        if extra or "task" not in value:
            raise PydanticCustomError(
                "link_shape",
                'a link is {{"task": id, "type": "FS" | "SS" | "FF" | "SF", "lag": minutes}}; '
                "{what}",
                {"what": f"unknown key {extra[0]!r}" if extra else "'task' is missing"},
            )
        return Link(_task_id(value["task"]), value.get("type", "FS"), value.get("lag", 0))
    return _task_id(value)


AfterEntry = Annotated[
    int | str | Link,
    PlainValidator(_after_entry, json_schema_input_type=int | str | LinkIn),
    PlainSerializer(lambda v: v.to_dict() if isinstance(v, Link) else v, return_type=Any),
    Field(description="A task id (finish to start, no lag) or a typed link"),
]
