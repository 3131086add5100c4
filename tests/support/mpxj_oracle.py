"""MPXJ (the `mpxj` package: the Java library through JPype) as the independent oracle for
app.exchange: it writes the schedules the readers import and reads the MSPDI the writer
makes. JPype starts one JVM per process and never a second, so `start_jvm` is idempotent
and the `mpxj` fixture (tests/conftest.py) is session-scoped."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import jpype


def start_jvm() -> None:
    import mpxj  # noqa: F401  (puts MPXJ's jars on the class path)

    if not jpype.isJVMStarted():
        jpype.startJVM(convertStrings=True)


@dataclass
class Spec:
    """One activity of a schedule MPXJ writes. `links`: (predecessor name, type, lag min)."""

    name: str
    hours: float
    features: str | None = None
    resources: tuple[str, ...] = ()
    links: tuple[tuple[str, str, float], ...] = ()
    release: datetime | None = None  # start no earlier than
    finish_by: datetime | None = None  # finish no later than
    deadline: datetime | None = None  # MS Project's Deadline (MSPDI only)
    milestone: bool = False
    extra: dict[str, Any] = field(default_factory=dict)


def _local(moment: datetime) -> Any:
    from java.time import LocalDateTime

    return LocalDateTime.of(
        moment.year, moment.month, moment.day, moment.hour, moment.minute, moment.second
    )


def build_project(name: str, start: datetime, specs: list[Spec]) -> Any:
    """An MPXJ ProjectFile: one summary task over the specs, Text1 aliased "Features",
    activity ids equal to the unique ids (so P6's task_code and MS Project's UID agree)."""
    from org.mpxj import (
        ConstraintType,
        Duration,
        ProjectFile,
        Relation,
        RelationType,
        TaskField,
        TimeUnit,
    )

    kinds = {
        "FS": RelationType.FINISH_START,
        "SS": RelationType.START_START,
        "FF": RelationType.FINISH_FINISH,
        "SF": RelationType.START_FINISH,
    }
    project = ProjectFile()
    props = project.getProjectProperties()
    props.setName(name)
    props.setStartDate(_local(start))
    project.setDefaultCalendar(project.addDefaultBaseCalendar())
    project.getCustomFields().getOrCreate(TaskField.TEXT1).setAlias("Features")
    summary = project.addTask()
    summary.setName("Works")
    summary.setActivityID(str(summary.getUniqueID()))
    resources: dict[str, Any] = {}
    tasks: dict[str, Any] = {}
    for spec in specs:
        task = summary.addTask()
        task.setName(spec.name)
        task.setActivityID(str(task.getUniqueID()))
        task.setDuration(Duration.getInstance(spec.hours, TimeUnit.HOURS))
        task.setStart(_local(start))
        if spec.milestone:
            task.setMilestone(True)
        if spec.features is not None:
            task.setText(1, spec.features)
        if spec.release is not None:
            task.setConstraintType(ConstraintType.START_NO_EARLIER_THAN)
            task.setConstraintDate(_local(spec.release))
        if spec.finish_by is not None:
            task.setConstraintType(ConstraintType.FINISH_NO_LATER_THAN)
            task.setConstraintDate(_local(spec.finish_by))
        if spec.deadline is not None:
            task.setDeadline(_local(spec.deadline))
        for resource_name in spec.resources:
            if resource_name not in resources:
                resources[resource_name] = project.addResource()
                resources[resource_name].setName(resource_name)
            task.addResourceAssignment(resources[resource_name])
        for pred, kind, lag in spec.links:
            task.addPredecessor(
                Relation.Builder()
                .predecessorTask(tasks[pred])
                .type(kinds[kind])
                .lag(Duration.getInstance(lag, TimeUnit.MINUTES))
            )
        tasks[spec.name] = task
    return project


def write(project: Any, fmt: str) -> bytes:
    from java.io import ByteArrayOutputStream
    from org.mpxj.mspdi import MSPDIWriter
    from org.mpxj.primavera import PrimaveraXERFileWriter

    writer = MSPDIWriter() if fmt == "mspdi" else PrimaveraXERFileWriter()
    out = ByteArrayOutputStream()
    writer.write(project, out)
    return bytes(out.toByteArray())


def read(data: bytes) -> Any:
    """A ProjectFile read by MPXJ's UniversalProjectReader (it detects the format)."""
    from java.io import ByteArrayInputStream
    from org.mpxj.reader import UniversalProjectReader

    return UniversalProjectReader().read(ByteArrayInputStream(data))


def to_datetime(value: Any) -> datetime:
    return datetime.fromisoformat(str(value.toString()))
