"""A run stops asking a model that keeps failing (docs/reasoners.md#bounded-cost).

After `after` decided tasks in a row ended in the rules fallback (every attempt at each was
unusable, or the server never answered: a transport failure after the SDK's own retries
ends in the fallback too), the model is given up: the rules reasoner answers every later
attempt of the run, its replies marked `why: "gave_up"`, and the run records the switch
once as an `llm_gave_up` event. 0 never gives up.

The count is the graph's own state (`failing`, checkpointed with each task's start), so a
run restarted after a crash counts on from where its record stands, as the token budget
reads its spent tokens back (app.reasoners.budget). Once given up the count is held, so
the run never goes back to the model: the rules' own decisions do not fall back and would
otherwise reset it. A task the rules reasoner answered as clear-cut (scope `contested`) is
not a fallback and ends the row; the row counts the tasks that asked the model and failed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from app.domain.lifecycle import EventKind

LLM_GAVE_UP = EventKind.LLM_GAVE_UP.value  # the run event recording the switch
DEFAULT_GIVE_UP_AFTER = 3


def given_up(failing: int, after: int) -> bool:
    return after > 0 and failing >= after


def next_failing(failing: int, fallback: bool, after: int) -> int:
    """The row after a decided task: one longer when it fell back, else none; held once
    the model is given up."""
    if given_up(failing, after):
        return failing
    return failing + 1 if fallback else 0


@dataclass(frozen=True)
class GaveUp:
    """When the run stopped asking its model: the first task the rule decided instead."""

    task_index: int
    failing: int  # tasks in a row that ended in the fallback
    after: int  # the setting that fired

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)
