"""The time fields of an instance in a request (docs/api.md#plans-in-time): minutes, durations, the
plan's start.

Only each value's own shape is checked here (a number of minutes, a map of them, a date-time
with an offset); what the fields mean together (every task timed, `after` naming known tasks
without a cycle, travel between every pair of zones in use, deadlines and shifts that can be
met) is the domain's to check (`app.domain.timing_rules`), whose errors name the field and
the task the same way.
"""

from __future__ import annotations

import math
from datetime import datetime
from typing import Annotated

from pydantic import BeforeValidator, Field, PlainValidator
from pydantic_core import PydanticCustomError

from app.domain.models import MAX_NAME_CHARS
from app.http.times import parse_rfc3339

# The longest span any minute value may name: about 19 years. Far past any site plan, yet
# it keeps every sum a schedule makes (10,000 tasks of it plus travel) an exact float and
# lets CP-SAT scale minutes to integer units without overflow.
MAX_MINUTES = 10_000_000

Minutes = Annotated[float, Field(ge=0, le=MAX_MINUTES, allow_inf_nan=False, strict=True)]
PositiveMinutes = Annotated[float, Field(gt=0, le=MAX_MINUTES, allow_inf_nan=False, strict=True)]


def _minutes_value(value: object, what: str) -> float | int:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise PydanticCustomError(
            "duration_type", "{what} must be a number of minutes", {"what": what}
        )
    if not math.isfinite(value) or not 0 < value <= MAX_MINUTES:
        # pydantic fills a template's `{name}` with str(value) and knows no format spec, so
        # the limit goes in already formatted.
        raise PydanticCustomError(
            "duration_range",
            "{what} must be more than 0 and at most {limit} minutes, got {got}",
            {"what": what, "limit": f"{MAX_MINUTES:,}", "got": value},
        )
    return value


def _duration(value: object) -> float | int | dict[str, float | int]:
    """One number of minutes, or a map robot name -> minutes (a robot it leaves out cannot
    take the task). One error naming the robot, rather than one per member of the union."""
    if not isinstance(value, dict):
        return _minutes_value(value, "a duration")
    if not value:
        raise PydanticCustomError(
            "duration_map_empty",
            # Not a `{{` escape: pydantic copies a template's braces as they are.
            "a duration map names at least one robot: {robot name: minutes}",
        )
    out: dict[str, float | int] = {}
    for name, minutes in value.items():
        if not isinstance(name, str) or not name.strip() or len(name) > MAX_NAME_CHARS:
            raise PydanticCustomError(
                "duration_robot",
                "the duration map's keys are robot names, got {got!r}",
                {"got": name},
            )
        out[name] = _minutes_value(minutes, f"the duration for robot '{name}'")
    return out


RobotKey = Annotated[str, Field(min_length=1, max_length=MAX_NAME_CHARS)]

# int beside float: a duration is kept as sent (20 stays 20 in what a run stores), and the
# serializer then finds the member a value is.
Duration = Annotated[
    int | float | dict[str, int | float],
    PlainValidator(
        _duration,
        json_schema_input_type=PositiveMinutes | dict[RobotKey, PositiveMinutes],
    ),
    Field(
        description="Minutes: one number for every robot, or a map {robot: minutes} naming "
        "every robot that may take the task (the others cannot)"
    ),
]

# The plan's minute 0 on the wall clock, kept in the offset it was sent in: a schedule's
# times (`start_at`, `end_at`, the calendar) are given in the site's own offset.
WallClock = Annotated[datetime, BeforeValidator(parse_rfc3339)]


# A shift is [start, end]; the domain checks that it ends after it starts.
Shift = Annotated[
    tuple[Minutes, Minutes],
    Field(description="The robot's shift [start, end], minutes from the plan's start"),
]
