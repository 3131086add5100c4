"""The success model, metrics, cap and phases of docs/allocation.md."""

from __future__ import annotations

import pytest

from app.domain.cap import WorkloadCap
from app.domain.catalog import scenario, scenarios, teach_tasks
from app.domain.errors import DomainError
from app.domain.metrics import (
    Severity,
    balance_score,
    compute_metrics,
    jain_index,
    severity,
    simulate_completion,
)
from app.domain.models import Instance, Robot, Task
from app.domain.phases import Phase, detect_phase


def test_teach_data_has_36_actions_in_spec_order() -> None:
    tasks = teach_tasks()
    assert len(tasks) == 36
    assert [t.id for t in tasks[:3]] == [0, 1, 2]
    assert tasks[14].name == "Navigation" and tasks[14].id == 300
    assert tasks[-1].name == "Beep" and tasks[-1].features == ("dexterous",)
    assert set(scenarios()) == {"baseline", "heavy_excels", "medium_excels", "light_excels"}


def test_success_is_the_mean_over_the_task_features() -> None:
    inst = scenario("baseline").instance
    backward = next(i for i, t in enumerate(inst.tasks) if t.name == "Backward")
    # heavy+careful: light (.5+.9)/2, medium (.7+.7)/2, heavy (.9+.5)/2
    assert list(inst.success[backward]) == pytest.approx([0.7, 0.7, 0.7])


@pytest.mark.parametrize(
    ("loads", "score", "level"),
    [
        ([12, 12, 12], 100.0, Severity.LOW),
        ([15, 12, 9], 75.0, Severity.LOW),
        ([18, 12, 6], 50.0, Severity.MODERATE),
        ([22, 10, 4], 16.666667, Severity.HIGH),
        ([36, 0, 0], 0.0, Severity.CRITICAL),
        ([19, 12, 5], 41.666667, Severity.HIGH),
    ],
)
def test_balance_score_and_severity(loads: list[int], score: float, level: Severity) -> None:
    assert balance_score(loads, 12) == pytest.approx(score, abs=1e-5)
    assert severity(loads, 12) is level


def test_jain_index_bounds() -> None:
    assert jain_index([12, 12, 12]) == pytest.approx(1.0)
    assert jain_index([36, 0, 0]) == pytest.approx(1 / 3)


@pytest.mark.parametrize(
    ("allocated", "phase"),
    [
        (0, Phase.EARLY),
        (32, Phase.EARLY),
        (33, Phase.MIDDLE),
        (66, Phase.MIDDLE),
        (67, Phase.LATE),
        (99, Phase.LATE),
    ],
)
def test_phase_boundaries(allocated: int, phase: Phase) -> None:
    assert detect_phase(allocated, 100) is phase


def test_cap_bounds_and_feasibility() -> None:
    cap = WorkloadCap(36, 3, 4)
    assert (cap.lower, cap.upper) == (8, 16)
    assert cap.infeasibility() is None
    # 37 tasks, no deviation allowed: 12.33 is not a whole number of tasks.
    assert "raise max_deviation" in (WorkloadCap(37, 3, 0).infeasibility() or "")
    assert WorkloadCap(36, 5, 0.5).infeasibility() is not None
    # With 10 tasks left and loads (16, 0, 0) the others can still reach 8 each? No: 16 > 10.
    assert not cap.can_complete([16, 0, 0], 10)
    assert cap.can_complete([16, 0, 0], 20)
    assert not cap.allows([16, 4, 4], 0, 12)


def test_simulated_completion_is_seeded_and_brackets_the_expectation() -> None:
    inst = scenario("baseline").instance
    assignment = [0] * 36
    a = simulate_completion(inst, assignment, seed=7, trials=2000)
    b = simulate_completion(inst, assignment, seed=7, trials=2000)
    assert a == b
    expected = float(inst.success[:, 0].mean())
    assert a.ci95[0] <= expected <= a.ci95[1]


def test_metrics_are_consistent() -> None:
    inst = scenario("baseline").instance
    m = compute_metrics(inst, [t % 3 for t in range(36)], seed=1)
    assert m.workload == {"light": 12, "medium": 12, "heavy": 12}
    assert m.balance_score == 100.0
    assert set(m.feature_success) == {"dexterous", "heavy", "careful"}


@pytest.mark.parametrize(
    ("tasks", "robots", "field"),
    [
        ((), (Robot("a", {"x": 1}),), "tasks"),
        ((Task(1, "t", ("x",)),), (), "robots"),
        ((Task(1, "t", ("x",)), Task(1, "u", ("x",))), (Robot("a", {"x": 1}),), "tasks.1.id"),
        ((Task(1, "t", ("y",)),), (Robot("a", {"x": 1}),), "tasks.0.features"),
        ((Task(1, "t", ("x",)),), (Robot("a", {"x": 1.5}),), "robots.0.success.x"),
        ((Task(1, "t", ("x",)),), (Robot("a", {"x": 1}), Robot("A", {"x": 1})), "robots.1.name"),
        ((Task(1, "t", ("x", "x")),), (Robot("a", {"x": 1}),), "tasks.0.features"),
        # A label that is another robot's name would make "**Decision**: b" ambiguous.
        (
            (Task(1, "t", ("x",)),),
            (Robot("a", {"x": 1}, label="b"), Robot("b", {"x": 1})),
            "robots.1.name",
        ),
        (
            (Task(1, "t", ("x",)),),
            (Robot("a", {"x": 1}, label="X"), Robot("b", {"x": 1}, label="x")),
            "robots.1.label",
        ),
        ((Task(1, "t", ("x",)),), (Robot("a", {"x": 1}, label="**bold**"),), "robots.0.label"),
        ((Task(1, "t", ("x",)),), (Robot("a:b", {"x": 1}),), "robots.0.name"),
    ],
)
def test_instance_validation_names_the_field(
    tasks: tuple[Task, ...], robots: tuple[Robot, ...], field: str
) -> None:
    with pytest.raises(DomainError) as err:
        Instance(tasks=tasks, robots=robots)
    assert err.value.field == field


@pytest.mark.parametrize("seed", range(20))
def test_cap_tracker_agrees_with_the_cap(seed: int) -> None:
    import random

    from app.domain.cap import CapTracker

    rng = random.Random(seed)
    n, r = rng.randint(1, 30), rng.randint(1, 5)
    cap = WorkloadCap(n, r, rng.choice([0, 0.5, 1, 2, 3]))
    if cap.infeasibility():
        return
    tracker, loads = CapTracker(cap), [0] * r
    for t in range(n):
        allowed = [i for i in range(r) if tracker.allows(i)]
        assert allowed == cap.feasible_robots(loads, n - t - 1)
        choice = rng.choice(allowed)
        tracker.assign(choice)
        loads[choice] += 1
    assert cap.respected_by(loads)


def test_a_label_equal_to_its_own_name_is_fine() -> None:
    Instance(tasks=(Task(1, "t", ("x",)),), robots=(Robot("a", {"x": 1}, label="A"),))
