"""From what a reader took out of a file to a draft instance (`app.exchange.model.Draft`).

The rules, the same for every format (docs/exchange.md says why each is so):
- a task is a leaf activity with a duration above zero and features (from the features
  field, else `default_features`); summary tasks and WBS levels are structure, not work;
- milestones (zero duration) are skipped and their links bridged;
- release and deadline count continuous minutes from the project's start (the plan's
  clock), while durations are the file's working minutes: the caveat `source` states;
- robots are the resources assigned to imported tasks, by name, with no rates yet; a task
  with several assigned resources and one feature is a team of that many robots;
- every item not imported is listed in `skipped` with why, and a cycle of links refuses
  the whole file (docs/schedules.md#links).
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import UTC, datetime
from typing import Any

from app.exchange.activity_links import bridge_milestones, refuse_cycles
from app.exchange.model import Activity, Draft, Link, ReadProject

CAVEAT = (
    "Durations and lags are the file's working minutes (its calendar's working time); the "
    "plan counts continuous minutes from `start`, so a task the file spreads over a night "
    "or a weekend is planned as one block. Model working hours with the robots' shifts "
    "(`available`)."
)
ZONE_NOTE = "The file's dates carry no time zone; they are read as UTC."


def _number(minutes: float) -> float | int:
    """Whole minutes as an int (the draft reads as a person would write it), else tenths:
    MSPDI keeps lags in tenths of a minute and XER hours round-trip to them."""
    value = round(minutes, 1)
    return int(value) if value == int(value) else value


def split_features(text: str | None) -> list[str]:
    out: list[str] = []
    for part in (text or "").split(","):
        name = part.strip()
        if name and name not in out:
            out.append(name)
    return out


def _minutes_from(start: datetime | None, moment: datetime | None) -> float | None:
    if start is None or moment is None:
        return None
    return (moment - start).total_seconds() / 60


def _as_utc(moment: datetime) -> datetime:
    return moment.replace(tzinfo=UTC) if moment.tzinfo is None else moment


def _is_task(a: Activity) -> bool:
    return not a.summary and not a.milestone and a.duration is not None and a.duration > 0


def _activity_skips(
    project: ReadProject, defaults: list[str]
) -> tuple[list[Activity], list[str], list[dict[str, Any]]]:
    """The activities that become tasks, the milestones, and the skipped activities."""
    tasks: list[Activity] = []
    milestones: list[str] = []
    skipped: list[dict[str, Any]] = []

    def skip(a: Activity, why: str) -> None:
        skipped.append({"kind": "activity", "id": a.id, "name": a.name, "why": why})

    field = project.features_field or "the features field"
    for a in project.activities:
        if a.summary:
            skip(a, a.summary_why)
        elif a.milestone or a.duration == 0:
            milestones.append(a.key)
            skip(a, "a milestone (zero duration): its links are bridged to its successors")
        elif a.duration is None or a.duration < 0:
            skip(a, "the file gives it no duration")
        elif not split_features(a.features) and not defaults:
            skip(a, f"no features in {field}; fill it in the file or pass default_features")
        else:
            tasks.append(a)
    return tasks, milestones, skipped


def build_draft(
    project: ReadProject, *, default_features: Sequence[str] | str | None = None
) -> Draft:
    defaults = (
        split_features(default_features)
        if isinstance(default_features, str)
        else list(dict.fromkeys(default_features or ()))
    )
    activities = {a.key: a for a in project.activities}
    tasks, milestones, skipped = _activity_skips(project, defaults)
    kept = {a.key for a in tasks}

    def label(key: str) -> str:
        a = activities.get(key)
        return a.id if a is not None else key

    usable: list[Link] = []
    for link in project.links:
        if link.refused is not None:
            skipped.append(_link_item(link, label, link.refused))
        else:
            usable.append(link)
    final: list[Link] = []
    for link in bridge_milestones(usable, milestones):
        missing = [k for k in (link.predecessor, link.successor) if k not in kept]
        if missing:
            why = "; ".join(_gone(activities.get(k), k) for k in missing)
            skipped.append(_link_item(link, label, why))
        else:
            final.append(link)
    refuse_cycles(final, {a.key: a.id for a in tasks})
    after: dict[str, list[dict[str, Any]]] = {a.key: [] for a in tasks}
    # In the file's task order, so the same project read from either format gives the same
    # lists whatever order each file keeps its links in.
    position = {a.key: i for i, a in enumerate(tasks)}
    final.sort(key=lambda k: (position[k.successor], position[k.predecessor], k.type, k.lag))
    for link in final:
        entry = {"task": label(link.predecessor), "type": link.type, "lag": _number(link.lag)}
        after[link.successor].append(entry)
    robots = _robots(tasks)
    out_tasks = [_task(a, after[a.key], defaults, project.start, skipped) for a in tasks]
    start = None if project.start is None else _as_utc(project.start).isoformat()
    source = {
        "format": project.format,
        "project": project.name,
        "calendar": project.calendar,
        "features_field": project.features_field,
        "read": {
            "activities": len(project.activities),
            "links": len(project.links),
            "resources": project.resources,
            "assignments": project.assignments,
        },
        "imported": {"tasks": len(out_tasks), "links": len(final), "robots": len(robots)},
        "caveats": [CAVEAT, ZONE_NOTE],
    }
    return Draft(out_tasks, robots, start, source, skipped)


def _gone(activity: Activity | None, key: str) -> str:
    if activity is None:
        return f"{key} is not in the file"
    if activity.summary:
        return f"{activity.id} is a summary task, which is not planned"
    return f"{activity.id} is not imported (see its own entry)"


def _link_item(link: Link, label: Any, why: str) -> dict[str, Any]:
    return {
        "kind": "link",
        "id": f"{label(link.predecessor)} -> {label(link.successor)}",
        "type": link.type,
        "lag": _number(link.lag),
        "why": why,
    }


def _robots(tasks: Sequence[Activity]) -> list[dict[str, Any]]:
    names: dict[str, None] = {}
    for a in tasks:
        for name in a.resources:
            names.setdefault(name)
    return [{"name": name, "success": {}} for name in names]


def _task(
    a: Activity,
    after: list[dict[str, Any]],
    defaults: list[str],
    start: datetime | None,
    skipped: list[dict[str, Any]],
) -> dict[str, Any]:
    features = split_features(a.features) or defaults
    task: dict[str, Any] = {
        "id": a.id,
        "name": a.name,
        "features": features,
        "duration": _number(float(a.duration or 0)),
        "after": after,
    }
    release = _minutes_from(start, a.release)
    if release is not None and release > 0:
        task["release"] = _number(release)
    deadline = _minutes_from(start, a.deadline)
    if deadline is not None:
        task["deadline"] = _number(deadline)
    resources = list(dict.fromkeys(a.resources))
    if resources:
        task["planned_robots"] = resources
    if len(resources) > 1 and len(features) == 1:
        # docs/allocation.md#teams: several robots at once on the one feature, in the shape
        # a request sends; planning a team in time is the planners' business.
        task["team"] = {features[0]: len(resources)}
    for kind, why in a.notes:
        skipped.append({"kind": kind, "id": a.id, "name": a.name, "why": why})
    return task
