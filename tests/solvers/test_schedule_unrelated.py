"""Sites where every robot has its own speed (issue 38; docs/schedules.md#the-generator,
#schedulers): the second family's generator, the slowness charged by the dispatch, the
gate that turns on the steps for unrelated robots (and leaves every other site as it
was), and the large path on the family: checked, deterministic, never longer with more
budget. Small sites and short deterministic budgets; the large path forced by lowering
its threshold."""

from __future__ import annotations

import itertools

import pytest

from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.scheduling.dispatch import dispatch_schedule
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.list_schedule import sequence_schedule
from app.domain.scheduling.zone_batches import batched_orders
from app.solvers.cpsat import search
from app.solvers.cpsat.bounds import chains
from app.solvers.cpsat.common import DET_PER_S, SuccessWeights, speeds_decide
from app.solvers.cpsat.large import _candidates
from app.solvers.cpsat.load_bound import load_relaxation
from app.solvers.cpsat.search import _setup
from benchmarks.fjs import DATA, read_fjs, shop_instance
from benchmarks.timed_instances import construction_site
from benchmarks.unrelated_sites import MINUTES, TRAVEL, unrelated_site


def unrelated(n_tasks: int, n_robots: int, seed: int = 0) -> Problem:
    return Problem.build(unrelated_site(n_tasks, n_robots, seed=seed), Mode.BALANCED, uncapped=True)


@pytest.fixture
def large_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(search, "EXACT_LIMIT", 0)


def test_the_generator_draws_the_family_it_documents() -> None:
    instance = unrelated_site(600, 12, seed=3)
    tm = Problem.build(instance, uncapped=True).instance.timing
    zones = range(len(tm.zones))
    assert len(tm.zones) == 4
    for a, b, c in itertools.product(zones, repeat=3):  # a metric: no way round is shorter
        assert tm.travel(a, c) <= tm.travel(a, b) + tm.travel(b, c)
    assert all(TRAVEL[0] <= tm.travel(a, b) <= TRAVEL[1] for a in zones for b in zones if a != b)
    durations = [tm.duration(t, r) for t in range(600) for r in range(12)]
    assert len(durations) == 600 * 12 and min(durations) >= MINUTES[0]
    assert max(durations) <= MINUTES[1]
    index = {t.id: i for i, t in enumerate(instance.tasks)}
    waiting = [t for t in instance.tasks if t.after]
    assert 0.55 < len(waiting) / 600 < 0.65
    for t in waiting:  # one or two of the 30 before it
        assert 1 <= len(t.after) <= 2
        assert all(0 < index[t.id] - index[str(a)] <= 30 for a in t.after)
    released = [t for t in instance.tasks if t.release is not None]
    assert 0.05 < len(released) / 600 < 0.15
    assert unrelated_site(600, 12, seed=3) == instance  # seeded


def test_slowness_gives_a_task_to_the_robot_quick_at_it() -> None:
    # Robot a is free now and takes 8 minutes; b takes 4 but is busy until 5 (9 in all).
    tasks = (
        Task(id="first", name="first", features=("w",), duration={"b": 5.0}),
        Task(id="next", name="next", features=("w",), duration={"a": 8.0, "b": 4.0}),
    )
    robots = (Robot(name="a", success={"w": 0.9}), Robot(name="b", success={"w": 0.9}))
    problem = Problem.build(Instance(tasks=tasks, robots=robots), uncapped=True)
    quotas = {(0, 1): 1, (1, 0): 1, (1, 1): 1}  # class 0: b alone; class 1: either
    plain = dispatch_schedule(problem, [0, 1], quotas)
    charged = dispatch_schedule(problem, [0, 1], quotas, slowness=1.0)
    assert list(plain.assignment) == [1, 0] and plain.makespan == 8
    assert list(charged.assignment) == [1, 1] and charged.makespan == 9
    assert check_schedule(problem, charged) == []


def _decides(problem: Problem) -> bool:
    tm = problem.instance.timing
    candidates = [tm.eligible_robots(t) for t in range(tm.n_tasks)]
    return speeds_decide(problem, SuccessWeights(problem), candidates)


def test_only_sites_where_the_speeds_decide_run_the_steps_for_unrelated_robots() -> None:
    assert _decides(unrelated(60, 4))
    # Kinds of robots whose success rates differ: the expected success chooses the robots.
    assert not _decides(Problem.build(construction_site(60, 4, zones=(2, 2)), Mode.BALANCED))
    # A flexible job shop: the speeds decide, but nothing travels.
    shop = shop_instance(read_fjs(DATA / "mk01.fjs"))
    assert not _decides(Problem.build(shop, Mode.BALANCED, uncapped=True))


def test_the_large_path_on_unrelated_robots_is_checked_deterministic_and_anytime(
    large_path: None,
) -> None:
    problem = unrelated(120, 4, seed=1)
    small = search.solve_schedule(problem, time_limit_s=2.0)
    again = search.solve_schedule(problem, time_limit_s=2.0)
    large = search.solve_schedule(problem, time_limit_s=4.0)
    assert "slowness charged" in small.model and "LNS" in large.model
    assert "zone-batched orders" in large.model  # with the sequencing, from about 2.5 s
    for answer in (small, large):
        assert check_schedule(problem, answer.schedule) == []
        assert answer.bound <= answer.makespan
    assert [(s.robot, s.start) for s in small.schedule.slots] == [
        (s.robot, s.start) for s in again.schedule.slots
    ]
    assert large.makespan <= small.makespan
    reached = [p for p in large.trajectory if p[0] <= 2.0 * DET_PER_S + 1e-6]
    assert reached and reached[-1][3] == small.makespan


def test_zone_batching_keeps_a_robot_in_its_zone_for_a_run_of_tasks() -> None:
    # One robot, four tasks alternating between two zones 5 minutes apart in queue order:
    # in that order it crosses three times; zone-batched, once.
    zones = ("A", "B", "A", "B")
    tasks = tuple(
        Task(id=f"t{i}", name=f"t{i}", features=("w",), duration={"a": 10.0}, zone=z)
        for i, z in enumerate(zones)
    )
    robots = (Robot(name="a", success={"w": 0.9}, zone="A"),)
    travel = {"A": {"B": 5.0}, "B": {"A": 5.0}}
    problem = Problem.build(Instance(tasks=tasks, robots=robots, travel=travel), uncapped=True)
    queue = sequence_schedule(problem, [[0, 1, 2, 3]])
    orders = batched_orders(problem, [0, 0, 0, 0], [0.0] * 4, 1.0, 0.5)
    batched = sequence_schedule(problem, orders)
    assert sorted(orders[0]) == [0, 1, 2, 3]
    assert check_schedule(problem, batched) == []
    assert [problem.instance.tasks[t].zone for t in orders[0]] == ["A", "A", "B", "B"]
    assert batched.robot_time[0].travel == 5.0 < queue.robot_time[0].travel == 15.0
    assert batched.makespan == 45.0 < queue.makespan == 55.0


def test_zone_batched_orders_keep_every_rule_on_the_family() -> None:
    problem = unrelated(150, 5, seed=2)
    tm = problem.instance.timing
    assignment = [min(range(5), key=lambda r: (tm.duration(t, r), r)) for t in range(150)]
    _, _, _, tails, _ = chains(problem)
    for travel in (0.0, 1.0, 4.0):
        orders = batched_orders(problem, assignment, list(tails), travel, 0.5)
        assert sorted(t for order in orders for t in order) == list(range(150))
        assert all(assignment[t] == r for r, order in enumerate(orders) for t in order)
        assert check_schedule(problem, sequence_schedule(problem, orders)) == []


def test_pricing_the_entries_more_never_lowers_the_load_lp_and_its_shares_are_whole_tasks() -> None:
    problem = unrelated(80, 4, seed=1)
    setup = _setup(problem, search.Search(10.0, 1, 0), None)
    candidates = [_candidates(setup, t) for t in range(problem.instance.n_tasks)]
    _, _, heads, tails, _ = chains(problem, setup.pairs)
    common = {
        "es_target": setup.es_target,
        "es_floor": setup.es_floor,
        "time_limit_s": 30.0,
        "heads": heads,
        "tails": tails,
    }
    once = load_relaxation(problem, candidates, setup.weights, **common)  # type: ignore[arg-type]
    thrice = load_relaxation(
        problem,
        candidates,
        setup.weights,
        entry_weight=3.0,
        **common,  # type: ignore[arg-type]
    )
    assert thrice.minutes >= once.minutes > 0
    for relaxation in (once, thrice):
        assert relaxation.shares is not None
        assert relaxation.shares.sum(axis=1) == pytest.approx(1.0, abs=1e-6)
        allowed = {(t, r) for t, robots in enumerate(candidates) for r in robots}
        assert all((t, r) in allowed for t, r in zip(*relaxation.shares.nonzero(), strict=True))


def test_each_budget_gets_what_the_trajectory_says_it_reaches(large_path: None) -> None:
    # Below the budget where step 2d and the sequencing fit, neither runs; the longer run's
    # trajectory must not claim their plan for those budgets (it did: 328 claimed at 1 s,
    # where a 1 s run answers 356).
    problem = unrelated(80, 4, seed=1)
    longest = search.solve_schedule(problem, time_limit_s=3.0)
    for limit in (1.0, 1.4, 2.0):
        alone = search.solve_schedule(problem, time_limit_s=limit)
        reached = [p for p in longest.trajectory if p[0] <= limit * DET_PER_S + 1e-6]
        assert reached and reached[-1][3] == alone.makespan, limit
        assert alone.budget["deterministic_used"] <= limit * DET_PER_S + 0.5  # no overrun
