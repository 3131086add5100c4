"""Which of a draft's links a run can plan today, and the draft as a run request.

/runs and /allocate take `after` as plain task ids (finish-to-start, no lag); typed links
with lags are planned once the solvers honour them (docs/exchange.md#not-built-yet). Until
then a draft is started only when every link is a plain finish-to-start with zero lag,
sent as plain ids: anything else would be planned as a different schedule than the file's.
"""

from __future__ import annotations

from typing import Any

from app.exchange.model import Draft

# What a request's task takes; `planned_robots` is the planner's intent, not a request field.
_TASK_KEYS = ("id", "name", "features", "duration", "release", "deadline")


def typed_links(draft: Draft) -> list[dict[str, Any]]:
    """Each link that is not a plain finish-to-start with zero lag: {"task", "after"
    (the predecessor), "type", "lag"}."""
    out = []
    for task in draft.tasks:
        for entry in task["after"]:
            if isinstance(entry, dict) and (entry.get("type", "FS") != "FS" or entry.get("lag")):
                out.append(
                    {
                        "task": task["id"],
                        "after": entry["task"],
                        "type": entry.get("type", "FS"),
                        "lag": entry.get("lag", 0),
                    }
                )
    return out


def plain_request(draft: Draft) -> dict[str, Any]:
    """The draft as a run request's `tasks`, `robots`, `start`, links as plain ids.
    ValueError when a link is typed (typed_links says which)."""
    typed = typed_links(draft)
    if typed:
        raise ValueError(f"{len(typed)} typed link(s) cannot be planned yet")
    tasks = []
    for task in draft.tasks:
        plain = {k: task[k] for k in _TASK_KEYS if k in task}
        plain["after"] = [e["task"] if isinstance(e, dict) else e for e in task["after"]]
        tasks.append(plain)
    out: dict[str, Any] = {"tasks": tasks, "robots": draft.robots}
    if draft.start is not None:
        out["start"] = draft.start
    return out
