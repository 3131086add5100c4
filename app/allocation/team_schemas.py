"""The request and answer fields of team tasks and robot skills (docs/allocation.md#teams),
added to the task, robot and assignment bodies of `app.allocation.schemas`."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, StrictInt, StrictStr
from pydantic_core import PydanticCustomError

from app.domain.models import MAX_NAME_CHARS
from app.http.fields import Name

# Feature names: every one must be rated by the robots, whose rate keys refuse NUL already.
Feature = Annotated[StrictStr, Field(min_length=1, max_length=MAX_NAME_CHARS)]

TEAM_FIELD = Field(
    None,
    max_length=100,
    description='Robots needed at once, per feature (docs/allocation.md#teams): {"heavy": 2, '
    '"careful": 1} is three distinct robots, two covering heavy, one careful',
)
SKILLS_FIELD = Field(
    None,
    max_length=100,
    description="Features it may work on (docs/allocation.md#teams): a single-robot task only "
    "if all its features are skills, a team unit only of a skill. Default: any task, and in "
    "a team any feature it rates above 0",
)
Team = dict[Feature, StrictInt]


def task_features(features: list[str], team: Team | None, features_sent: bool) -> tuple[str, ...]:
    """A task's features: as sent, or its team's keys; a task needs one or the other."""
    if not features_sent and team is None:
        raise PydanticCustomError(
            "features_required", "give the features the task needs (`features`), or a `team`"
        )
    return tuple(features if features_sent or team is None else team)


class TeamMemberOut(BaseModel):
    robot: str
    feature: str = Field(description="The feature of the unit this member covers")


MEMBERS_FIELD = Field(
    None,
    description="Team tasks only (docs/allocation.md#teams): one entry per unit, in the team's "
    "key order",
    exclude_if=lambda members: members is None,
)


class TeamMemberIn(BaseModel):
    """One unit of a team as a request gives it (a pin in /allocate, a review's override)."""

    model_config = ConfigDict(extra="forbid")

    robot: Name = Field(description="Robot name (or label)")
    feature: Feature = Field(description="The feature of the unit this robot covers")


# A team in a request: one entry per unit, the members of one feature in any order.
TEAM_IN_FIELD = Field(
    None,
    min_length=1,
    max_length=100,
    description="Team tasks only (docs/allocation.md#teams): the whole team, one "
    '{"robot", "feature"} per unit, each robot distinct and able to cover its feature',
)
