"""Writing a plan as MS Project XML (app.exchange.write_mspdi): MPXJ, the independent
oracle, reads it with the plan's dates, links and assignments, and importing it gives back
the draft the plan was made from (docs/exchange.md#export)."""

from __future__ import annotations

from datetime import timedelta
from functools import cache
from typing import Any

import pytest

from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.schedule import Schedule
from app.exchange import Draft, read_mspdi, write_mspdi
from tests.support.exchange_support import files, plan_of
from tests.support.mpxj_oracle import read, to_datetime

pytestmark = pytest.mark.usefixtures("mpxj")


@cache
def exported() -> tuple[Draft, Problem, Schedule, bytes]:
    draft = read_mspdi(files()["mspdi"], features_field="Text1")
    problem, schedule = plan_of(draft)
    # The plan honours the file's typed links (docs/schedules.md#links) before it is written.
    assert check_schedule(problem, schedule) == []
    data = write_mspdi(problem, schedule, project_name="Level 2 slab plan")
    return draft, problem, schedule, data


def without_planned(tasks: list[dict[str, Any]]) -> list[dict[str, Any]]:
    # The plan's robots are the export's assignments, not the file's: compared on their own.
    return [{k: v for k, v in t.items() if k != "planned_robots"} for t in tasks]


def test_the_export_imports_back_to_the_same_draft() -> None:
    draft, problem, schedule, data = exported()
    again = read_mspdi(data, features_field="Text1")
    assert without_planned(again.tasks) == without_planned(draft.tasks)
    assert again.start == draft.start
    # The plan's robots are the ones the export assigns: a team task every member, so it
    # reads back as the team it was (docs/allocation.md#teams).
    robots = problem.instance.robots
    assert [t["planned_robots"] for t in again.tasks] == [
        [robots[r].name for r in s.members] for s in schedule.slots
    ]
    assert [t.get("team") for t in again.tasks] == [t.get("team") for t in draft.tasks]
    assert again.source["calendar"] == "24 Hours"
    assert again.skipped == []


def test_mpxj_reads_the_plans_dates_links_and_assignments() -> None:
    draft, problem, schedule, data = exported()
    project = read(data)
    assert str(project.getProjectProperties().getName()) == "Level 2 slab plan"
    origin = schedule.start
    assert origin is not None
    kinds = {"FINISH_START": "FS", "START_START": "SS", "FINISH_FINISH": "FF", "START_FINISH": "SF"}
    seen = {}
    for task in project.getTasks():
        if task.getName() is None:
            continue  # MPXJ's own project summary task
        seen[str(task.getName())] = task
    tasks = problem.instance.tasks
    by_id = {t["id"]: t for t in draft.tasks}
    for slot in schedule.slots:
        task = tasks[slot.task]
        read_back = seen[task.name]
        wall = origin.replace(tzinfo=None)
        assert to_datetime(read_back.getStart()) == wall + timedelta(minutes=slot.start)
        assert to_datetime(read_back.getFinish()) == wall + timedelta(minutes=slot.end)
        duration = read_back.getDuration()
        assert str(duration.getUnits()) in ("MINUTES", "m")
        assert float(duration.getDuration()) == pytest.approx(slot.end - slot.start)
        assert str(read_back.getText(1)) == ",".join(task.features)
        links = sorted(
            (
                str(r.getPredecessorTask().getText(2)),
                kinds[str(r.getType().name())],
                float(r.getLag().getDuration()),
            )
            for r in read_back.getPredecessors()
        )
        wanted = sorted(
            (a["task"], a["type"], float(a["lag"])) for a in by_id[str(task.id)]["after"]
        )
        assert links == wanted
        assigned = [str(a.getResource().getName()) for a in read_back.getResourceAssignments()]
        # One assignment per (task, member): MPXJ reads a team task's members too.
        assert assigned == [problem.instance.robots[r].name for r in slot.members]
    assert len(seen) == len(tasks)
    names = {str(r.getName()) for r in project.getResources() if r.getName() is not None}
    assert names == {r.name for r in problem.instance.robots}
    alias = project.getCustomFields().get(__import__("org.mpxj").mpxj.TaskField.TEXT1).getAlias()
    assert str(alias) == "Features"


def test_ids_that_are_not_whole_numbers_are_kept_in_the_task_id_field() -> None:
    from datetime import UTC, datetime

    from app.domain.models import Instance, Robot, Task
    from app.domain.modes import Mode
    from app.domain.scheduling.list_schedule import list_schedule

    instance = Instance(
        tasks=(
            Task(id="A-10", name="Pour & <cure>", features=("pour",), duration=30),
            Task(id=7, name="Screed", features=("pour",), duration=12.5, after=("A-10",)),
        ),
        robots=(Robot(name="Crane, north", success={"pour": 0.9}),),
        start=datetime(2026, 3, 2, 7, 0, tzinfo=UTC),
    )
    problem = Problem.build(instance, Mode.BALANCED, uncapped=True)
    schedule = list_schedule(problem, [0, 0])
    data = write_mspdi(problem, schedule)
    draft = read_mspdi(data)
    assert [(t["id"], t["name"], t["duration"]) for t in draft.tasks] == [
        ("A-10", "Pour & <cure>", 30),
        ("7", "Screed", 12.5),
    ]
    assert draft.tasks[1]["after"] == [{"task": "A-10", "type": "FS", "lag": 0}]
    project = read(data)
    assert sorted(str(t.getName()) for t in project.getTasks() if t.getName()) == [
        "Pour & <cure>",
        "Screed",
    ]
