"""The shared serial list scheduler, earliest-finish dispatch, and the hook that gives every
method's answer a schedule on a timed instance (docs/schedules.md#schedulers)."""

from __future__ import annotations

from collections import Counter

import pytest

from app.domain.catalog import scenario, timed_scenario
from app.domain.errors import DomainError
from app.domain.metrics import expected_success
from app.domain.models import Instance
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.scheduling.dispatch import dispatch_schedule, quotas_of
from app.domain.scheduling.feasibility import Rule, check_schedule
from app.domain.scheduling.list_schedule import list_schedule, sequence_schedule
from app.solvers.cpsat.common import task_classes, time_free_optimum
from app.solvers.registry import get_solver
from app.solvers.timed import attach_schedule
from benchmarks.timed_instances import construction_site
from tests.support.timed_support import robot, task, two_zone_site


def test_earliest_start_in_precedence_order_by_hand() -> None:
    problem = Problem.build(two_zone_site(), Mode.SUCCESS_FOCUSED)
    schedule = list_schedule(problem, [1, 0, 1])
    # s (in B) takes t3 first (released at 2, no travel), then travels to A for t1;
    # r (in A) travels to B meanwhile and starts t2 once t1 has ended.
    assert [(s.robot, s.start, s.end, s.travel) for s in schedule.slots] == [
        (1, 10, 15, 4),
        (0, 15, 18, 4),
        (1, 2, 6, 0),
    ]
    assert schedule.makespan == 18
    assert check_schedule(problem, schedule) == []


def test_a_deadline_the_assignment_cannot_meet_is_reported_not_hidden() -> None:
    inst = Instance(
        tasks=(task(0, duration=10), task(1, duration=10, deadline=12)),
        robots=(robot("r"), robot("s")),
    )
    problem = Problem.build(inst, Mode.SUCCESS_FOCUSED)
    schedule = list_schedule(problem, [0, 0])
    assert [s.start for s in schedule.slots] == [0, 10]
    assert [v.rule for v in check_schedule(problem, schedule)] == [Rule.DEADLINE]


def test_tasks_go_around_a_pinned_start() -> None:
    inst = Instance(
        tasks=(task(0, duration=5), task(1, duration=12), task(2, duration=4)),
        robots=(robot("r"),),
    )
    problem = Problem.build(inst, Mode.SUCCESS_FOCUSED, pinned={2: 0}, pinned_starts={2: 10})
    schedule = list_schedule(problem, [0, 0, 0])
    # 5 minutes fit before the fixed task at 10-14; 12 do not, so they go after it.
    assert [(s.start, s.end) for s in schedule.slots] == [(0, 5), (14, 26), (10, 14)]
    assert check_schedule(problem, schedule) == []


def test_nothing_without_a_fixed_start_begins_before_not_before() -> None:
    problem = Problem.build(two_zone_site(), Mode.SUCCESS_FOCUSED, not_before=20)
    schedule = list_schedule(problem, [0, 0, 1])
    assert min(s.start for s in schedule.slots) == 20
    assert check_schedule(problem, schedule) == []


def test_sequences_are_timed_as_given_and_contradictions_refused() -> None:
    problem = Problem.build(two_zone_site(), Mode.SUCCESS_FOCUSED)
    schedule = sequence_schedule(problem, [[0, 2, 1], []])
    assert [(s.start, s.end) for s in schedule.slots] == [(0, 5), (13, 16), (9, 13)]
    with pytest.raises(ValueError, match="contradict"):
        sequence_schedule(problem, [[1, 0, 2], []])


def test_an_assignment_to_a_robot_that_cannot_take_the_task_has_no_schedule() -> None:
    problem = Problem.build(two_zone_site(), Mode.SUCCESS_FOCUSED)
    with pytest.raises(DomainError) as err:
        list_schedule(problem, [0, 1, 0])
    assert err.value.field == "assignment.1" and err.value.code == "ineligible"
    assert "'s' cannot take task 2" in err.value.message


def test_dispatch_keeps_every_quota_and_so_the_expected_success() -> None:
    inst = construction_site(60, 6, seed=3)
    problem = Problem.build(inst, Mode.BALANCED)
    flow = time_free_optimum(problem)
    classes = task_classes(problem)
    schedule = dispatch_schedule(problem, classes, quotas_of(flow, classes))
    assert quotas_of(schedule.assignment, classes) == quotas_of(flow, classes)
    assert Counter(schedule.assignment) == Counter(flow)
    assert expected_success(inst, schedule.assignment) == pytest.approx(
        expected_success(inst, flow)
    )
    assert check_schedule(problem, schedule) == []
    assert schedule.makespan < list_schedule(problem, flow).makespan


@pytest.mark.parametrize("name", ["greedy", "dp", "optimal", "q_learning", "ltaa"])
def test_every_method_gets_a_list_schedule_on_a_timed_instance(name: str) -> None:
    problem = Problem.build(timed_scenario("baseline_timed").instance, Mode.BALANCED)
    options = {"episodes": 200} if name == "q_learning" else None
    solution = get_solver(name).solve(problem, seed=1, options=options)
    schedule = solution.details["schedule"]
    assert schedule.assignment == solution.assignment
    assert solution.details["schedule_violations"] == check_schedule(problem, schedule)
    # The LTAA graph decides in time order and keeps the times it gave
    # (docs/schedules.md#runs-in-time); every other method is timed by the list scheduler.
    timed_by = "LTAA graph's own times" if name == "ltaa" else "list scheduler"
    assert timed_by in solution.details["schedule_model"]


def test_untimed_answers_carry_no_schedule() -> None:
    solution = get_solver("greedy").solve(Problem.build(scenario("baseline").instance))
    assert solution.details == {}


def test_an_assignment_with_an_ineligible_robot_gets_no_schedule_and_says_why() -> None:
    inst = Instance(
        tasks=(task(0, duration={"weak": 5}), task(1, duration=5)),
        robots=(robot("strong", 0.9), robot("weak", 0.4)),
    )
    problem = Problem.build(inst, Mode.SUCCESS_FOCUSED)
    # Every method honours eligibility now (docs/allocation.md#teams): dp gives task 0 to
    # the only robot with a duration for it, and gets a schedule.
    solution = get_solver("dp").solve(problem)
    assert solution.assignment[0] == 1
    assert solution.details["schedule"] is not None
    # The shared list scheduler still refuses an assignment that breaks the rule, and says why.
    details: dict[str, object] = {}
    attach_schedule(problem, [0, 0], details)
    assert details["schedule"] is None
    assert "'strong' cannot take task 0" in str(details["schedule_error"])
