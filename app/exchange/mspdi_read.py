"""Microsoft Project XML (MSPDI) into a `ReadProject`.

What is read (docs/exchange.md#mspdi): the project's Name, StartDate and calendar; each
Task's UID, Name, Summary, Milestone, Duration (ISO 8601, working time), ConstraintType
and ConstraintDate, Deadline, extended attributes (the features field) and
PredecessorLinks (Type, LinkLag in tenths of a minute, LagFormat, CrossProject); the
Resources and Assignments. Everything else in the file is left alone.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from datetime import datetime

from app.exchange.errors import ExchangeError
from app.exchange.model import Activity, Link, LinkType, ReadProject
from app.exchange.xml_safe import parse_xml

NAMESPACE = "http://schemas.microsoft.com/project"
TEXT1 = "188743731"  # MS Project's FieldID of Text1, defined or not in the file
TEXT2 = "188743734"
ID_ALIAS = "Task id"  # the field app.exchange.mspdi_write keeps a plan's task ids in
LINK_TYPES: dict[str, LinkType] = {"0": "FF", "1": "FS", "2": "SF", "3": "SS"}
PERCENT_LAGS = {"19", "20", "51", "52"}  # LagFormat: % (elapsed, estimated) of the duration
UNASSIGNED = "-65535"  # an Assignment's ResourceUID when no resource is assigned
_DURATION = re.compile(
    r"^(-)?P(?:(\d+(?:\.\d+)?)Y)?(?:(\d+(?:\.\d+)?)M)?(?:(\d+(?:\.\d+)?)D)?"
    r"(?:T(?:(\d+(?:\.\d+)?)H)?(?:(\d+(?:\.\d+)?)M)?(?:(\d+(?:\.\d+)?)S)?)?$"
)


_Q = f"{{{NAMESPACE}}}"


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


class _Fields:
    """An element's child values by local name. Looked up by the few names the reader
    needs (ElementTree's findtext, in C) rather than by walking every child in Python: an
    MPXJ-written task has some 60 children, a 10,000-task file 600,000 of them."""

    __slots__ = ("element",)

    def __init__(self, element: ET.Element) -> None:
        self.element = element

    def get(self, name: str, default: str = "") -> str:
        text = self.element.findtext(_Q + name)
        return default if text is None else text.strip()


def _fields(element: ET.Element) -> _Fields:
    return _Fields(element)


def _children(element: ET.Element | None, name: str) -> list[ET.Element]:
    return [] if element is None else element.findall(_Q + name)


def _child(element: ET.Element, name: str) -> ET.Element | None:
    return element.find(_Q + name)


def _date(text: str | None) -> datetime | None:
    if not text:
        return None
    try:
        return datetime.fromisoformat(text)
    except ValueError:
        raise ExchangeError(
            f"the date {text!r} is not an ISO 8601 date-time", code="malformed"
        ) from None


def duration_minutes(text: str, minutes_per_day: float) -> float | None:
    """Working minutes of an MSPDI duration (PT8H0M0S); None for months or years, which
    have no fixed length in working time."""
    match = _DURATION.match(text)
    if match is None:
        raise ExchangeError(f"the duration {text!r} is not ISO 8601 (PT8H0M0S)", code="malformed")
    sign, years, months, days, hours, minutes, seconds = match.groups()
    if years or months:
        return None
    total = float(days or 0) * minutes_per_day
    total += float(hours or 0) * 60 + float(minutes or 0) + float(seconds or 0) / 60
    return -total if sign else total


def _field_ids(root: ET.Element, wanted: str | None) -> tuple[str | None, str | None, str | None]:
    """(features FieldID, its name as the file has it, the task-id FieldID or None)."""
    defined: list[tuple[str, str, str]] = []
    for attribute in _children(_child(root, "ExtendedAttributes"), "ExtendedAttribute"):
        f = _fields(attribute)
        defined.append((f.get("FieldID", ""), f.get("FieldName", ""), f.get("Alias", "")))
    id_field = next((fid for fid, _, alias in defined if alias == ID_ALIAS), None)
    if wanted is None:
        hit = next((d for d in defined if d[2].lower() == "features"), None)
        return (hit[0], hit[2], id_field) if hit else (TEXT1, "Text1", id_field)
    key = wanted.strip().lower()
    for fid, name, alias in defined:
        if key in (fid, name.lower(), alias.lower()):
            return fid, alias or name, id_field
    if key == "text1":
        return TEXT1, "Text1", id_field
    have = ", ".join(f"{n} ({a})" if a else n for _, n, a in defined) or "none"
    raise ExchangeError(
        f"features_field {wanted!r} is not a field of this file; its custom fields: {have}",
        code="unknown_field",
        field="features_field",
    )


def _links(task: ET.Element, uid: str, uids: set[str]) -> list[Link]:
    out: list[Link] = []
    for element in _children(task, "PredecessorLink"):
        f = _fields(element)
        pred = f.get("PredecessorUID", "")
        kind: LinkType = LINK_TYPES.get(f.get("Type", "1"), "FS")
        lag = float(f.get("LinkLag") or 0) / 10
        refused = None
        if f.get("CrossProject") == "1":
            other = f.get("CrossProjectName") or "another project"
            refused = f"a link to a task in {other}: only this file's tasks are planned"
        elif pred not in uids:
            refused = f"its predecessor (UID {pred}) is not in the file"
        elif f.get("LagFormat") in PERCENT_LAGS:
            refused = "a lag in percent of the predecessor's duration: give it in minutes"
        out.append(Link(pred, uid, kind, lag, refused))
    return out


_ATTRIBUTE, _FIELD_ID, _VALUE = _Q + "ExtendedAttribute", _Q + "FieldID", _Q + "Value"


def _task(
    element: ET.Element, feature_id: str | None, id_field: str | None, mpd: float
) -> Activity:
    # findtext straight on the element: this runs for every task of a 10,000-task file.
    find = element.findtext
    uid = (find(_Q + "UID") or "").strip()
    values = {
        (a.findtext(_FIELD_ID) or "").strip(): (a.findtext(_VALUE) or "").strip()
        for a in element.iterfind(_ATTRIBUTE)
    }
    text = (find(_Q + "Duration") or "").strip()
    duration = duration_minutes(text, mpd) if text else None
    activity = Activity(
        id=(values.get(id_field) if id_field else None) or uid,
        key=uid,
        name=(find(_Q + "Name") or "").strip() or uid,
        duration=duration,
        summary=find(_Q + "Summary") == "1" or find(_Q + "OutlineLevel") == "0",
        milestone=find(_Q + "Milestone") == "1",
        features=values.get(feature_id) if feature_id else None,
    )
    f = _fields(element)
    constraint, date = f.get("ConstraintType", "0"), _date(f.get("ConstraintDate"))
    if constraint == "4":
        activity.release = date
    elif constraint == "7":
        activity.deadline = date
    elif constraint not in ("0", "1"):
        activity.notes.append(
            (
                "constraint",
                f"constraint type {constraint} is not imported: the plan takes "
                "start-no-earlier-than, finish-no-later-than and deadlines only",
            )
        )
    deadline = _date(f.get("Deadline"))
    if deadline is not None and (activity.deadline is None or deadline < activity.deadline):
        activity.deadline = deadline
    return activity


def read_mspdi_project(data: bytes, features_field: str | None = None) -> ReadProject:
    root = parse_xml(data)
    if _local(root.tag) != "Project" or not root.tag.startswith(f"{{{NAMESPACE}}}"):
        raise ExchangeError(
            f"expected MS Project XML (MSPDI: a <Project> element in {NAMESPACE}); found an "
            f"XML document whose root is <{root.tag}>",
            code="wrong_format",
        )
    head = _fields(root)
    mpd = float(head.get("MinutesPerDay") or 480)  # a day's working minutes
    calendars = {
        _fields(c).get("UID"): _fields(c).get("Name")
        for c in _children(_child(root, "Calendars"), "Calendar")
    }
    feature_id, feature_name, id_field = _field_ids(root, features_field)
    elements = [
        t for t in _children(_child(root, "Tasks"), "Task") if t.findtext(_Q + "IsNull") != "1"
    ]
    activities = [_task(t, feature_id, id_field, mpd) for t in elements]
    by_uid = {a.key: a for a in activities}
    uids = set(by_uid)
    links = [
        link
        for element, a in zip(elements, activities, strict=True)
        for link in _links(element, a.key, uids)
    ]
    resources = {
        f.get("UID", ""): f.get("Name") or f"resource {f.get('UID', '')}"
        for f in map(_fields, _children(_child(root, "Resources"), "Resource"))
        if f.get("UID") != "0"  # MS Project's unnamed resource 0 stands for "none"
    }
    assigned = 0
    for f in map(_fields, _children(_child(root, "Assignments"), "Assignment")):
        task, resource = by_uid.get(f.get("TaskUID", "")), resources.get(f.get("ResourceUID", ""))
        if task is not None and resource is not None:
            task.resources.append(resource)
            assigned += 1
    return ReadProject(
        format="mspdi",
        name=head.get("Name") or head.get("Title") or None,
        start=_date(head.get("StartDate")),
        calendar=calendars.get(head.get("CalendarUID")),
        activities=activities,
        links=links,
        resources=len(resources),
        assignments=assigned,
        features_field=feature_name,
    )
