"""Primavera P6 XER into a `ReadProject`.

What is read (docs/exchange.md#xer): the first project of the file (PROJECT: its start,
calendar, and the name of its root WBS node), its activities (TASK: task_code, name,
type, original duration in hours, constraints), links (TASKPRED: pred_type, lag_hr_cnt),
resources and assignments (RSRC, TASKRSRC), and the features field from a user field
(UDFTYPE, UDFVALUE) or an activity code (ACTVTYPE, ACTVCODE, TASKACTV).
"""

from __future__ import annotations

from collections import defaultdict
from datetime import datetime

from app.exchange.errors import ExchangeError
from app.exchange.model import Activity, Link, LinkType, ReadProject
from app.exchange.xer import Table, parse_tables

LINK_TYPES: dict[str, LinkType] = {"PR_FS": "FS", "PR_SS": "SS", "PR_FF": "FF", "PR_SF": "SF"}
MILESTONES = {"TT_Mile", "TT_FinMile"}
STRUCTURE = {
    "TT_WBS": "a WBS summary activity: structure, not work",
    "TT_LOE": "a level-of-effort activity: it spans other activities, it is not work itself",
}
RELEASE, DEADLINE = "CS_MSOA", "CS_MEOB"  # start on or after; finish on or before
NO_DATE = {"", "CS_ALAP"}  # as late as possible is a scheduling choice, not a date


def _date(text: str | None) -> datetime | None:
    if not text:
        return None
    try:
        return datetime.fromisoformat(text.strip())
    except ValueError:
        raise ExchangeError(
            f"the date {text!r} is not a P6 date (2026-03-02 08:00)", code="malformed"
        ) from None


def _hours(text: str | None) -> float | None:
    if text is None or not text.strip():
        return None
    try:
        return float(text) * 60
    except ValueError:
        raise ExchangeError(f"the hours {text!r} are not a number", code="malformed") from None


def _feature_values(
    tables: dict[str, Table], wanted: str | None
) -> tuple[dict[str, str], str | None]:
    """task_id -> the features field's text, and the field's name as the file has it."""
    key = (wanted or "Features").strip().lower()
    for udf in tables.get("UDFTYPE", []):
        names = (udf.get("udf_type_label", ""), udf.get("udf_type_name", ""))
        if udf.get("table_name") == "TASK" and key in (n.lower() for n in names):
            type_id = udf.get("udf_type_id")
            values = {
                v.get("fk_id", ""): v.get("udf_text") or v.get("udf_number") or ""
                for v in tables.get("UDFVALUE", [])
                if v.get("udf_type_id") == type_id
            }
            return values, names[0] or names[1]
    for code_type in tables.get("ACTVTYPE", []):
        if code_type.get("actv_code_type", "").lower() == key:
            type_id = code_type.get("actv_code_type_id")
            codes = {
                c.get("actv_code_id"): c.get("short_name") or c.get("actv_code_name") or ""
                for c in tables.get("ACTVCODE", [])
                if c.get("actv_code_type_id") == type_id
            }
            joined: dict[str, list[str]] = defaultdict(list)
            for row in tables.get("TASKACTV", []):
                if row.get("actv_code_type_id") == type_id and row.get("actv_code_id") in codes:
                    joined[row.get("task_id", "")].append(codes[row["actv_code_id"]])
            return {t: ",".join(v) for t, v in joined.items()}, code_type.get("actv_code_type")
    if wanted is None:
        return {}, None
    have = [
        u.get("udf_type_label") or u.get("udf_type_name", "") for u in tables.get("UDFTYPE", [])
    ]
    have += [c.get("actv_code_type", "") for c in tables.get("ACTVTYPE", [])]
    raise ExchangeError(
        f"features_field {wanted!r} is neither a user field nor an activity code of this "
        f"file; it has: {', '.join(h for h in have if h) or 'none'}",
        code="unknown_field",
        field="features_field",
    )


def _activity(row: dict[str, str], features: dict[str, str]) -> Activity:
    task_id, kind = row.get("task_id", ""), row.get("task_type", "")
    duration = _hours(row.get("target_drtn_hr_cnt"))
    if duration is None:
        duration = _hours(row.get("remain_drtn_hr_cnt"))
    activity = Activity(
        id=row.get("task_code") or task_id,
        key=task_id,
        name=row.get("task_name") or row.get("task_code") or task_id,
        duration=duration,
        summary=kind in STRUCTURE,
        summary_why=STRUCTURE.get(kind, ""),
        milestone=kind in MILESTONES,
        features=features.get(task_id),
    )
    for type_field, date_field in (("cstr_type", "cstr_date"), ("cstr_type2", "cstr_date2")):
        constraint, date = row.get(type_field, ""), _date(row.get(date_field))
        if constraint == RELEASE:
            activity.release = date
        elif constraint == DEADLINE:
            activity.deadline = date
        elif constraint not in NO_DATE:
            activity.notes.append(
                (
                    "constraint",
                    f"constraint {constraint} is not imported: the plan takes start "
                    "on or after (CS_MSOA) and finish on or before (CS_MEOB) only",
                )
            )
    return activity


def _links(tables: dict[str, Table], keys: set[str], every_task: dict[str, str]) -> list[Link]:
    out: list[Link] = []
    for row in tables.get("TASKPRED", []):
        succ, pred = row.get("task_id", ""), row.get("pred_task_id", "")
        if succ not in keys:
            continue  # another project's link
        refused = None
        if pred not in keys:
            if pred in every_task:
                refused = (
                    f"a link to an activity of another project (project {every_task[pred]}): "
                    "only the file's first project is planned"
                )
            else:
                refused = (
                    f"its predecessor (task_id {pred}, project {row.get('pred_proj_id') or '?'})"
                    " is not in the file: a cross-project link"
                )
        kind = LINK_TYPES.get(row.get("pred_type", "PR_FS"), "FS")
        out.append(Link(pred, succ, kind, _hours(row.get("lag_hr_cnt")) or 0.0, refused))
    return out


def read_xer_project(data: bytes, features_field: str | None = None) -> ReadProject:
    tables = parse_tables(data)
    projects = tables.get("PROJECT", [])
    if not projects:
        raise ExchangeError(
            "the XER file has no PROJECT table: nothing to import", code="malformed"
        )
    project = projects[0]
    proj_id = project.get("proj_id", "")
    features, field_name = _feature_values(tables, features_field)
    rows = [r for r in tables.get("TASK", []) if r.get("proj_id") == proj_id]
    activities = [_activity(r, features) for r in rows]
    by_key = {a.key: a for a in activities}
    every_task = {r.get("task_id", ""): r.get("proj_id", "") for r in tables.get("TASK", [])}
    resources = {
        r.get("rsrc_id", ""): r.get("rsrc_name") or r.get("rsrc_short_name", "")
        for r in tables.get("RSRC", [])
    }
    assigned = 0
    for row in tables.get("TASKRSRC", []):
        activity, name = by_key.get(row.get("task_id", "")), resources.get(row.get("rsrc_id", ""))
        if activity is not None and name:
            activity.resources.append(name)
            assigned += 1
    calendars = {c.get("clndr_id"): c for c in tables.get("CALENDAR", [])}
    calendar = calendars.get(project.get("clndr_id")) or next(
        (c for c in calendars.values() if c.get("default_flag") == "Y"), None
    )
    root = next(
        (
            w
            for w in tables.get("PROJWBS", [])
            if w.get("proj_id") == proj_id and w.get("proj_node_flag") == "Y"
        ),
        None,
    )
    return ReadProject(
        format="xer",
        name=(root or {}).get("wbs_name") or project.get("proj_short_name") or None,
        start=_date(project.get("plan_start_date")),
        calendar=None if calendar is None else calendar.get("clndr_name"),
        activities=activities,
        links=_links(tables, set(by_key), every_task),
        resources=len(resources),
        assignments=assigned,
        features_field=field_name,
    )
