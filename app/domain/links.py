"""Links between tasks: the one place their meaning is written (docs/schedules.md#links).

A task's `after` lists its predecessors: a plain id is a finish-to-start link with no lag,
an object `{"task", "type", "lag"}` a typed one. Each link says that one point of the
successor (its start for FS and SS, its end for FF and SF) comes no earlier than `lag`
minutes after one point of the predecessor (its end for FS and FF, its start for SS and
SF); a negative lag is a lead. So every link is a lower bound on the successor, and once
a task's predecessors are placed, `earliest_start` says when its links let it start on a
robot taking `duration` minutes: every scheduler places tasks in a precedence order and
asks it, the CP-SAT models add `required` as constraints, the feasibility check asks
`gap`.

The link graph has no cycle (checked in `check_links`), as Primavera P6 and MS Project
refuse circular relationships: a planner places each task after its predecessors, which a
cycle (even one whose lags leave room, such as two tasks that start together) prevents.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from app.domain.errors import DomainError

LinkType = Literal["FS", "SS", "FF", "SF"]
LINK_TYPES: tuple[str, ...] = ("FS", "SS", "FF", "SF")
MAX_LAG = 10_000_000  # minutes either way, as every other time field
# Start or end times per task index: a list, or an array (the bounds keep theirs in numpy).
Times = Sequence[float] | NDArray[np.float64]
_WORDS = {"S": "starts", "F": "ends"}


@dataclass(frozen=True)
class Link:
    """A typed `after` entry as a request sends it; checked by `check_links`, so `type`
    and `lag` hold whatever was sent until then."""

    task: int | str
    type: Any = "FS"
    lag: Any = 0

    def to_dict(self) -> dict[str, Any]:
        return {"task": self.task, "type": self.type, "lag": self.lag}


class Arc(NamedTuple):
    """A checked link into a task: its predecessor's index, type and lag in minutes."""

    pred: int
    type: str
    lag: float

    @property
    def plain(self) -> bool:
        return self.type == "FS" and self.lag == 0

    @property
    def from_start(self) -> bool:
        """Does the link count from the predecessor's start (SS, SF) rather than its end?"""
        return self.type[0] == "S"

    @property
    def to_end(self) -> bool:
        """Does it bound the successor's end (FF, SF) rather than its start?"""
        return self.type[1] == "F"


def allowed_start(arc: Arc, duration: float, pred_start: float, pred_end: float) -> float:
    """The earliest start this one link allows a task taking `duration` minutes, its
    predecessor running [pred_start, pred_end]: FS end + lag, SS start + lag, FF end + lag
    - duration, SF start + lag - duration."""
    point = pred_start if arc.from_start else pred_end
    return point + arc.lag - (duration if arc.to_end else 0.0)


def required(arc: Arc, starts: Times, ends: Times) -> float:
    """The time the successor's bound point (start or end) may not precede."""
    return allowed_start(arc, 0.0, starts[arc.pred], ends[arc.pred])


def earliest_start(arcs: Sequence[Arc], duration: float, starts: Times, ends: Times) -> float:
    """The earliest start a task's links allow, taking `duration` minutes, its
    predecessors placed at `starts`/`ends` (0 when it has none; callers add release).
    `allowed_start` for each link, written out: every scheduler calls this per task."""
    best = 0.0
    for pred, kind, lag in arcs:
        if kind == "FS":
            at = ends[pred] + lag
        elif kind == "SS":
            at = starts[pred] + lag
        elif kind == "FF":
            at = ends[pred] + lag - duration
        else:
            at = starts[pred] + lag - duration
        if at > best:
            best = at
    return best


def tail_through(arc: Arc, pred_longest: float, succ_shortest: float, succ_tail: float) -> float:
    """A lower bound on the time from a predecessor's end to the makespan through one link
    to a successor that takes at least `succ_shortest` and has `succ_tail` after its end
    (a link from the predecessor's start counts from up to `pred_longest` before its end)."""
    back = pred_longest if arc.from_start else 0.0
    return max(0.0, arc.lag - back + (0.0 if arc.to_end else succ_shortest) + succ_tail)


def ancestors_through(arc: Arc, pred_mask: int) -> int:
    """The tasks (a bitmask) that end before the successor starts in every schedule,
    learnt through this link from `pred_mask`, those that end before the predecessor
    starts: FS with lag >= 0 passes them and the predecessor, SS with lag >= 0 passes them
    (nothing else bounds the successor's start by their end)."""
    if arc.lag < 0:
        return 0
    if arc.type == "FS":
        return pred_mask | (1 << arc.pred)
    return pred_mask if arc.type == "SS" else 0


def gap(
    arc: Arc, start: float, end: float, starts: Sequence[float], ends: Sequence[float]
) -> float:
    """How far the successor's bound point is past what the link requires (< 0: broken)."""
    return (end if arc.to_end else start) - required(arc, starts, ends)


def describe(arc: Arc) -> str:
    """'an SS link, lag +20 min' (empty for a plain finish-to-start link)."""
    if arc.plain:
        return ""
    article = "an" if arc.type[0] in "SF" else "a"
    return f"{article} {arc.type} link, lag {arc.lag:+g} min"


def explain(arc: Arc, pred: str) -> str:
    """The link in words, as the graph's prompt shows it: "starts at least 20 min after
    'pour' starts (SS +20)"."""
    when = (
        f"at least {arc.lag:g} min after"
        if arc.lag > 0
        else "no earlier than"
        if arc.lag == 0
        else f"up to {-arc.lag:g} min before"
    )
    return f"{_WORDS[arc.type[1]]} {when} {pred} {_WORDS[arc.type[0]]} ({arc.type} {arc.lag:+g})"


def broken(
    arc: Arc, times: tuple[float, float], starts: Sequence[float], ends: Sequence[float], pred: str
) -> str:
    """What a broken link says, after the task's label: 'starts at 5, before task 'a' ...
    ends at 8' (`times`: the task's start and end; `pred`: the predecessor's label)."""
    start, end = times
    own = end if arc.to_end else start
    theirs = starts[arc.pred] if arc.from_start else ends[arc.pred]
    if arc.plain:
        return f"starts at {own:g}, before {pred} ends at {theirs:g}"
    return (
        f"{_WORDS[arc.type[1]]} at {own:g}, before minute {required(arc, starts, ends):g} that "
        f"{describe(arc)} from {pred} asks ({pred} {_WORDS[arc.type[0]]} at {theirs:g})"
    )


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def check_links(
    ids: Sequence[int | str], afters: Sequence[Any], labels: Sequence[str]
) -> tuple[tuple[Arc, ...], ...]:
    """Each task's links as arcs, or a DomainError naming the field
    (`tasks.4.after.1.type`) and how to fix it; then a cycle is refused naming it."""
    index = {str(t): k for k, t in enumerate(ids)}
    out: list[tuple[Arc, ...]] = []
    for i, after in enumerate(afters):
        if isinstance(after, str | bytes) or not isinstance(after, Sequence):
            raise DomainError(f"tasks.{i}.after", "must be a list of task ids or links")
        arcs: list[Arc] = []
        for j, entry in enumerate(after):
            arcs.append(_arc(f"tasks.{i}.after.{j}", entry, index, (i, labels[i]), arcs))
        out.append(tuple(arcs))
    _refuse_cycle(out, ids)
    return tuple(out)


_SHAPE = '{"task": id, "type": "FS" | "SS" | "FF" | "SF", "lag": minutes}'


def _arc(
    field: str, entry: Any, index: dict[str, int], own: tuple[int, str], seen: list[Arc]
) -> Arc:
    i, label = own
    typed = isinstance(entry, dict | Link)
    if isinstance(entry, dict):
        extra = sorted(set(entry) - {"task", "type", "lag"})
        if extra or "task" not in entry:
            what = f"unknown key {extra[0]!r}" if extra else "'task' is missing"
            raise DomainError(field, f"{label}: a link is {_SHAPE}; {what}", code="link_shape")
        entry = Link(entry["task"], entry.get("type", "FS"), entry.get("lag", 0))
    link = entry if isinstance(entry, Link) else Link(entry)
    if link.type not in LINK_TYPES:
        raise DomainError(
            f"{field}.type",
            f"{label}: link type {link.type!r} is not one of FS, SS, FF, SF (finish-to-start, "
            "start-to-start, finish-to-finish, start-to-finish); leave it out for FS",
            code="link_type",
        )
    if not _number(link.lag):
        raise DomainError(
            f"{field}.lag",
            f"{label}: a link's lag is a number of minutes (negative for a lead), got {link.lag!r}",
            code="link_lag",
        )
    where = f"{field}.task" if typed else field
    k = index.get(str(link.task))
    if k is None:
        raise DomainError(
            where,
            f"{label} waits for unknown task id {link.task!r}; no task in the queue has it",
            code="unknown_task",
        )
    if k == i and typed:  # a plain id naming its own task is the one-task cycle, as always
        raise DomainError(
            where,
            f"{label} waits for itself; a task cannot follow itself: remove this entry",
            code="self_link",
        )
    # Two links of different types between one pair are allowed (P6 keeps SS and FF
    # together); the same type twice says nothing new.
    if any(a.pred == k and a.type == link.type for a in seen):
        raise DomainError(
            field,
            f"{label} lists task {link.task!r} twice with type {link.type}; once is enough",
            code="duplicate_link",
        )
    return Arc(k, str(link.type), float(link.lag))


def _refuse_cycle(arcs: Sequence[Sequence[Arc]], ids: Sequence[int | str]) -> None:
    cycle = find_cycle([[a.pred for a in row] for row in arcs])
    if not cycle:
        return
    steps, plain = [], True
    for a, b in itertools.pairwise(cycle):
        arc = next(x for x in arcs[b] if x.pred == a)
        plain = plain and arc.plain
        steps.append(f"{ids[a]!r}" + ("" if arc.plain else f" ({arc.type} {arc.lag:+g} min)"))
    chain = " -> ".join([*steps, repr(ids[cycle[-1]])])
    why = (
        "each must end before the next starts"
        if plain
        else "a plan places each task after its predecessors, so no cycle of links can be "
        "planned, whatever its lags"
    )
    raise DomainError(
        f"tasks.{cycle[1]}.after",
        f"precedence cycle: {chain} ({why}); remove one of these 'after' entries",
        code="precedence_cycle",
    )


def find_cycle(predecessors: Sequence[Sequence[int]]) -> list[int]:
    """One precedence cycle as task indexes [a, b, ..., a] (each waits for the next's
    predecessor...): a depth-first search for a back edge. Empty if acyclic."""
    n = len(predecessors)
    state = [0] * n  # 0 new, 1 on the current path, 2 done
    for root in range(n):
        if state[root]:
            continue
        path: list[int] = []
        stack: list[tuple[int, int]] = [(root, 0)]
        while stack:
            node, i = stack.pop()
            if i == 0:
                state[node] = 1
                path.append(node)
            preds = predecessors[node]
            if i < len(preds):
                stack.append((node, i + 1))
                nxt = preds[i]
                if state[nxt] == 1:
                    cycle = path[path.index(nxt) :]
                    # path runs task -> predecessor; reverse so it reads "a before b"
                    cycle.reverse()
                    return [*cycle, cycle[0]]
                if state[nxt] == 0:
                    stack.append((nxt, 0))
            else:
                state[node] = 2
                path.pop()
    return []
