"""Time in living plans (docs/living-plans.md#a-revision-in-time) on domain objects: a timed
revision's Problem (reported times pinned, nothing before `now`, delays), an unrevised run's
schedule re-timed by its reports, and the diff's time moves. Checked against the rules written out
in tests/support/time_rules.py, not through the app's check_schedule alone."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

import pytest

from app.domain.catalog import scenario, timed_scenario
from app.domain.errors import DomainError
from app.domain.scheduling.feasibility import Rule, check_schedule
from app.domain.scheduling.list_schedule import list_schedule
from app.domain.scheduling.reported import Reported, retime
from app.domain.scheduling.schedule import Schedule
from app.graph.recorder import DecisionRecord
from app.plans.revision_pins import ParentDecision
from app.plans.revision_plan import RevisionPlan, plan_revision
from app.plans.revision_times import ReportedTimes
from app.plans.schedule_moves import Timed, time_moves
from app.runs.spec import RunSpec
from app.solvers.registry import get_solver
from tests.support.time_rules import Report, TimeRules

INSTANCE = timed_scenario("baseline_timed").instance
START = INSTANCE.start
assert START is not None
LATE = 25.0  # minutes the late task ran over


def record(problem: Any, task: int, robot: int) -> DecisionRecord:
    inst = problem.instance
    return DecisionRecord(
        task_index=task,
        task_id=inst.tasks[task].id,
        task_name=inst.tasks[task].name,
        robot=robot,
        robot_name=inst.robots[robot].name,
        phase="early",
        expected_success=float(inst.success[task, robot]),
        reasoning="",
        confidence="High",
        tradeoff="",
        quality=1.0,
        fallback=False,
        attempts=1,
        failure_log=[],
        loads_before=[0] * inst.n_robots,
        loads_after=[0] * inst.n_robots,
        balance_before=100.0,
        balance_after=100.0,
        severity_after="low",
    )


@dataclass
class Parent:
    spec: RunSpec
    planned: Schedule
    decided: dict[int, ParentDecision]

    @property
    def robot_names(self) -> list[str]:
        return [r.name for r in self.spec.problem.instance.robots]


def parent(instance: Any = INSTANCE) -> Parent:
    spec = RunSpec.for_instance(instance, mode="balanced")
    problem = spec.problem
    assignment = get_solver("greedy").solve(problem).assignment
    planned = list_schedule(problem, assignment) if instance.timed else None
    decided = {
        t: ParentDecision(record(problem, t, r), f"hash-{t}") for t, r in enumerate(assignment)
    }
    return Parent(spec, planned, decided)  # type: ignore[arg-type]


def at(minute: float) -> datetime:
    assert START is not None
    return START + timedelta(minutes=minute)


def site_reports(p: Parent, reported: range) -> tuple[dict[int, Report], int]:
    """What happened to the `reported` tasks: each robot did them in its planned order,
    the last one still running, the others done; one done task (returned) ran LATE minutes
    over and pushed that robot's later reported tasks."""
    slots = p.planned.slots
    robots = [[t for t in seq if t in reported] for seq in p.planned.sequences(3)]
    tm = INSTANCE.timing
    late = min(
        t for seq in robots for t in seq[:-1] if any(s not in reported for s in tm.successors[t])
    )
    out: dict[int, Report] = {}
    for seq in robots:
        shift = 0.0
        for k, t in enumerate(seq):
            start, end = slots[t].start + shift, slots[t].end + shift
            if t == late:
                end += LATE
                shift += LATE
            out[t] = Report("started", start) if k == len(seq) - 1 else Report("done", start, end)
    return out, late


def times(reports: dict[int, Report]) -> dict[int, ReportedTimes]:
    return {
        t: ReportedTimes(r.state, at(r.start), None if r.end is None else at(r.end))
        for t, r in reports.items()
    }


def revise(p: Parent, reports: dict[int, Report], changes: list[dict[str, Any]], now: Any) -> Any:
    return plan_revision(
        parent_spec=p.spec,
        decided=p.decided,
        execution={t: r.state for t, r in reports.items()},
        changes=changes,
        pin="reported",
        reasoner=None,
        model=None,
        parent_id="parent",
        token_budget=None,
        reports=times(reports),
        now=now,
        arrival=at(10_000),
    )


def slots_of(problem: Any, schedule: Schedule) -> dict[str, tuple[str, float, float]]:
    tasks, robots = problem.instance.tasks, problem.instance.robots
    return {str(tasks[s.task].id): (robots[s.robot].name, s.start, s.end) for s in schedule.slots}


def planned_schedule(plan: RevisionPlan) -> Schedule:
    solution = get_solver("greedy").solve(plan.problem)
    schedule = solution.details["schedule"]
    assert isinstance(schedule, Schedule)
    return schedule


def test_a_revision_pins_reported_times_plans_nothing_before_now_and_delays() -> None:
    p = parent()
    reports, late = site_reports(p, range(11))
    now = max(r.start for r in reports.values()) + 5
    tm = INSTANCE.timing
    delayed = next(t for t in range(11, tm.n_tasks) if tm.successors[t])
    changes: list[dict[str, Any]] = [
        {"type": "delay", "task_id": INSTANCE.tasks[delayed].id, "minutes": 30},
        {"type": "robot_unavailable", "robot": "heavy"},
    ]
    plan = revise(p, reports, changes, at(now))
    names = p.robot_names
    robot_of = {t: names[p.planned.slots[t].robot] for t in reports}
    # Started on the robot that broke down: not pinned, planned afresh (docs/living-plans.md#pins).
    kept = {
        t: r for t, r in reports.items() if not (r.state == "started" and robot_of[t] == "heavy")
    }
    assert kept != reports or "heavy" not in robot_of.values()
    assert plan.problem.not_before == pytest.approx(now)
    assert plan.spec.not_before == pytest.approx(now)
    assert dict(plan.problem.pinned_starts) == pytest.approx({t: r.start for t, r in kept.items()})
    assert plan.now == at(now)
    schedule = planned_schedule(plan)
    rules = TimeRules(
        parent_tasks=p.spec.instance_data["tasks"],
        reports={str(INSTANCE.tasks[t].id): r for t, r in kept.items()},
        now=now,
        delays={str(INSTANCE.tasks[delayed].id): 30.0},
        unavailable={"heavy"},
        parent_robots={str(INSTANCE.tasks[t].id): robot_of[t] for t in kept},
    )
    assert rules.broken(slots_of(plan.problem, schedule)) == []
    # The late task's successors wait for its real end.
    late_end = reports[late].end
    assert late_end is not None
    for s in tm.successors[late]:
        assert schedule.slots[s].start >= late_end
    # The app's own check agrees on every rule the revision is about.
    about = {Rule.PIN, Rule.NOT_BEFORE, Rule.PRECEDENCE, Rule.OVERLAP, Rule.DURATION}
    assert [v for v in check_schedule(plan.problem, schedule) if v.rule in about] == []
    # The spec a restart rebuilds the revision from gives the same problem.
    again = RunSpec.from_json(plan.spec.to_json()).problem
    assert dict(again.pinned_starts) == dict(plan.problem.pinned_starts)
    assert again.not_before == plan.problem.not_before
    assert again.instance == plan.problem.instance


def test_a_task_still_running_at_now_ends_no_earlier_than_now() -> None:
    p = parent()
    first = p.planned.sequences(3)[0][0]
    slot = p.planned.slots[first]
    reports = {first: Report("started", slot.start)}
    now = slot.end + 40  # it should have ended 40 minutes ago
    plan = revise(p, reports, [], at(now))
    index = [str(t.id) for t in plan.problem.instance.tasks].index(str(INSTANCE.tasks[first].id))
    assert plan.facts[index] == pytest.approx((slot.start, now))
    schedule = planned_schedule(plan)
    assert schedule.slots[index].end == pytest.approx(now)


def test_the_default_now_is_the_arrival_and_an_early_arrival_plans_from_the_start() -> None:
    p = parent()
    late_arrival = plan_revision(
        parent_spec=p.spec,
        decided=p.decided,
        execution={},
        changes=[],
        pin="reported",
        reasoner=None,
        model=None,
        parent_id="parent",
        token_budget=None,
        arrival=at(90),
    )
    assert late_arrival.problem.not_before == pytest.approx(90)
    early = plan_revision(
        parent_spec=p.spec,
        decided=p.decided,
        execution={},
        changes=[],
        pin="reported",
        reasoner=None,
        model=None,
        parent_id="parent",
        token_budget=None,
        arrival=at(-60),
    )
    assert early.problem.not_before == 0


@pytest.mark.parametrize(
    ("changes", "now", "field", "code"),
    [
        ([{"type": "delay", "task_id": "nope", "minutes": 5}], 0, "changes.0.task_id", None),
        ([{"type": "delay", "task_id": 200, "minutes": 0}], 0, "changes.0.minutes", None),
        ([{"type": "delay", "task_id": 200, "minutes": -3}], 0, "changes.0.minutes", None),
        ([], -1, "now", "before_start"),
        (
            [
                {"type": "remove_tasks", "task_ids": [200]},
                {"type": "delay", "task_id": 200, "minutes": 5},
            ],
            0,
            "changes.1.task_id",
            None,
        ),
    ],
)
def test_bad_time_input_names_the_field(
    changes: list[dict[str, Any]], now: float, field: str, code: str | None
) -> None:
    with pytest.raises(DomainError) as caught:
        revise(parent(), {}, changes, at(now))
    assert caught.value.field == field
    if code is not None:
        assert caught.value.code == code


def test_a_done_task_cannot_be_delayed() -> None:
    p = parent()
    first = p.planned.sequences(3)[0][0]
    slot = p.planned.slots[first]
    reports = {first: Report("done", slot.start, slot.end)}
    task_id = INSTANCE.tasks[first].id
    with pytest.raises(DomainError) as caught:
        revise(p, reports, [{"type": "delay", "task_id": task_id, "minutes": 5}], at(slot.end))
    assert caught.value.field == "changes.0.task_id"
    assert caught.value.code == "task_done"


def test_an_untimed_run_refuses_delay_and_plans_as_before_with_now() -> None:
    untimed = parent(scenario("baseline").instance)
    with pytest.raises(DomainError) as caught:
        revise(untimed, {}, [{"type": "delay", "task_id": 3, "minutes": 5}], None)
    assert caught.value.field == "changes.0"
    plan = revise(untimed, {}, [], datetime.fromisoformat("2026-12-01T09:00:00+00:00"))
    assert plan.spec.pinned_starts is None and plan.spec.not_before is None and plan.now is None
    assert plan.problem.not_before == 0 and not plan.problem.pinned_starts
    assert plan.spec.instance_data == untimed.spec.instance_data


def test_a_removed_task_hands_its_predecessors_to_its_successors() -> None:
    tm = INSTANCE.timing
    middle = next(t for t in range(tm.n_tasks) if tm.predecessors[t] and tm.successors[t])
    before, after = tm.predecessors[middle][0], tm.successors[middle][0]
    ids = [t.id for t in INSTANCE.tasks]
    plan = revise(parent(), {}, [{"type": "remove_tasks", "task_ids": [ids[middle]]}], at(0))
    tasks = {str(t.id): t for t in plan.problem.instance.tasks}
    assert str(ids[middle]) not in tasks
    assert ids[before] in tasks[str(ids[after])].after


def test_an_unrevised_run_is_retimed_by_its_reports_keeping_each_robots_order() -> None:
    p = parent()
    problem, planned = p.spec.problem, p.planned
    sequences = planned.sequences(3)
    tm = INSTANCE.timing
    # A task that has successors (on its robot and by precedence), done LATE minutes late.
    late = next(t for t in tm.order if tm.successors[t] and any(t in s[:-1] for s in sequences))
    slot = planned.slots[late]
    view = retime(problem, planned, {late: Reported(slot.start, slot.end + LATE)})
    assert (view.slots[late].start, view.slots[late].end) == (slot.start, slot.end + LATE)
    assert view.sequences(3) == sequences  # nobody changed robot or order
    # What waits for it (precedence, or the same robot after it), directly or not, may move
    # later, never earlier; everything else keeps its time.
    following = {s: [] for s in range(tm.n_tasks)}  # type: dict[int, list[int]]
    for t in range(tm.n_tasks):
        following[t].extend(tm.successors[t])
    for seq in sequences:
        for a, b in itertools.pairwise(seq):
            following[a].append(b)
    downstream, stack = set(), [late]
    while stack:
        for s in following[stack.pop()]:
            if s not in downstream:
                downstream.add(s)
                stack.append(s)
    for t in range(tm.n_tasks):
        if t == late:
            continue
        if t in downstream:
            assert view.slots[t].start >= planned.slots[t].start - 1e-9
        else:
            assert (view.slots[t].start, view.slots[t].end) == (
                planned.slots[t].start,
                planned.slots[t].end,
            )
    direct = [s for s in tm.successors[late]]
    assert direct and all(view.slots[s].start >= slot.end + LATE for s in direct)
    assert any(view.slots[s].start > planned.slots[s].start for s in direct)
    assert view.makespan >= planned.makespan
    rules = TimeRules(
        parent_tasks=p.spec.instance_data["tasks"],
        reports={str(INSTANCE.tasks[late].id): Report("done", slot.start, slot.end + LATE)},
        now=0.0,
    )
    assert rules.broken(slots_of(problem, view)) == []


def test_retime_with_a_started_task_and_a_task_reported_done_without_a_start() -> None:
    p = parent()
    problem, planned = p.spec.problem, p.planned
    a, b = p.planned.sequences(3)[0][:2]
    sa, sb = planned.slots[a], planned.slots[b]
    view = retime(problem, planned, {a: Reported(None, sa.end + 10), b: Reported(sa.end + 12)})
    d = sa.end - sa.start
    assert (view.slots[a].start, view.slots[a].end) == (sa.start + 10, sa.end + 10)
    assert (view.slots[b].start, view.slots[b].end) == (
        sa.end + 12,
        sa.end + 12 + (sb.end - sb.start),
    )
    assert d > 0


def test_time_moves_list_what_moved_with_wall_clock_times_and_the_makespans() -> None:
    p = parent()
    problem, planned = p.spec.problem, p.planned
    late = planned.sequences(3)[0][0]
    slot = planned.slots[late]
    view = retime(problem, planned, {late: Reported(slot.start, slot.end + LATE)})
    moves = time_moves(Timed(problem, planned), Timed(problem, view))
    moved = {m["task_id"]: m for m in moves["moves"]}
    changed = {
        INSTANCE.tasks[t].id
        for t in range(INSTANCE.n_tasks)
        if (view.slots[t].start, view.slots[t].end)
        != (planned.slots[t].start, planned.slots[t].end)
    }
    assert set(moved) == changed and INSTANCE.tasks[late].id in moved
    m = moved[INSTANCE.tasks[late].id]
    assert (m["start_moved"], m["end_moved"]) == (0, LATE)
    assert m["end_after_at"] == at(slot.end + LATE).isoformat()
    assert m["start_before_at"] == m["start_after_at"] == at(slot.start).isoformat()
    assert moves["makespan_before"] == {
        "minutes": planned.makespan,
        "at": at(planned.makespan).isoformat(),
    }
    assert moves["makespan_after"]["minutes"] == view.makespan
    same = time_moves(Timed(problem, planned), Timed(problem, planned))
    assert same["moves"] == []


def test_the_rules_checker_catches_each_broken_rule() -> None:
    """tests/support/time_rules.py is what the API and e2e tests trust: shown able to fail."""
    tasks: list[dict[str, Any]] = [
        {"id": "a", "duration": 10},
        {"id": "b", "duration": {"r": 5, "s": 8}, "after": ["a"]},
        {"id": "c", "duration": 4},
    ]
    rules = TimeRules(
        parent_tasks=tasks,
        reports={"a": Report("done", 0, 12)},
        now=20,
        delays={"c": 2},
        unavailable={"s"},
        parent_robots={"a": "r"},
    )
    good = {"a": ("r", 0.0, 12.0), "b": ("r", 20.0, 25.0), "c": ("r", 25.0, 31.0)}
    assert rules.broken(good) == []
    bad = {
        "reported start moved": {**good, "a": ("r", 1.0, 12.0)},
        "reported end moved": {**good, "a": ("r", 0.0, 10.0)},
        "reported robot changed": {**good, "a": ("t", 0.0, 12.0)},
        "before now": {**good, "b": ("r", 19.0, 24.0)},
        "unavailable robot": {**good, "b": ("s", 20.0, 28.0)},
        "delay ignored": {**good, "c": ("r", 25.0, 29.0)},
        "overlap": {**good, "c": ("r", 22.0, 28.0)},
    }
    for what, slots in bad.items():
        assert rules.broken(slots), what
    # b starts before a (its `after`) has ended.
    fresh = TimeRules(parent_tasks=tasks, reports={}, now=0)
    assert fresh.broken({"a": ("r", 0, 10), "b": ("s", 9, 17), "c": ("t", 0, 4)})
    assert fresh.broken({"a": ("r", 0, 10), "b": ("s", 10, 18), "c": ("t", 0, 4)}) == []
    started = TimeRules(parent_tasks=tasks, reports={"a": Report("started", 0)}, now=20)
    assert started.broken({"a": ("r", 0, 10), "b": ("r", 20, 25), "c": ("r", 25, 29)})
