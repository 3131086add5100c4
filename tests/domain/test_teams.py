"""Team tasks and skills (docs/allocation.md#teams): the exact solvers against an exhaustive
search written here, greedy's teams, and the instance rules."""

from __future__ import annotations

import itertools
import math
from fractions import Fraction

import pytest
from hypothesis import HealthCheck, event, given, reject, settings
from hypothesis import strategies as st

from app.domain.errors import DomainError, InfeasibleCapError
from app.domain.metrics import compute_metrics, expected_success, workload
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.solvers.registry import get_solver

FEATURES = ("heavy", "careful")
EXACT = ("brute_force", "dp", "optimal")


def _covers(robot: Robot, feature: str) -> bool:
    if robot.skills is not None:
        return feature in robot.skills
    return robot.success[feature] > 0


def _takes(robot: Robot, task: Task) -> bool:
    return robot.skills is None or set(task.features) <= set(robot.skills)


def _choices(instance: Instance, t: int) -> list[tuple[int, ...]]:
    """Every way to staff task t: one robot, or one distinct robot per unit (ordered)."""
    task, robots = instance.tasks[t], instance.robots
    if task.team is None:
        return [(r,) for r, robot in enumerate(robots) if _takes(robot, task)]
    units = [f for f, c in task.team.items() for _ in range(c)]
    return [
        team
        for team in itertools.permutations(range(len(robots)), len(units))
        if all(_covers(robots[r], f) for r, f in zip(team, units, strict=True))
    ]


def _success(instance: Instance, t: int, members: tuple[int, ...]) -> Fraction:
    task, robots = instance.tasks[t], instance.robots
    rate = {
        r.name: {f: Fraction(round(p * 100), 100) for f, p in r.success.items()} for r in robots
    }
    if task.team is None:
        name = robots[members[0]].name
        return sum((rate[name][f] for f in task.features), Fraction(0)) / len(task.features)
    units = [f for f, c in task.team.items() for _ in range(c)]
    total = sum((rate[robots[r].name][f] for r, f in zip(members, units, strict=True)), Fraction(0))
    return total / len(units)


def exhaustive(instance: Instance, cap: float | None) -> tuple[Fraction, int] | None:
    """The best (sum of success, deviation units) over every staffing within the cap, in
    exact arithmetic; None if no staffing fits. Loads count a team task once per member."""
    r = instance.n_robots
    n = sum(sum(t.team.values()) if t.team else 1 for t in instance.tasks)
    w = Fraction(n, r)
    lo = 0 if cap is None else max(0, math.ceil(w - Fraction(str(cap))))
    hi = n if cap is None else math.floor(w + Fraction(str(cap)))
    best: tuple[Fraction, int] | None = None
    options = [_choices(instance, t) for t in range(instance.n_tasks)]
    for plan in itertools.product(*options):
        loads = [0] * r
        for members in plan:
            for m in members:
                loads[m] += 1
        if not all(lo <= x <= hi for x in loads):
            continue
        value = sum((_success(instance, t, m) for t, m in enumerate(plan)), Fraction(0))
        dev = sum(abs(r * x - n) for x in loads)
        if best is None or value > best[0] or (value == best[0] and dev < best[1]):
            best = (value, dev)
    return best


@st.composite
def team_instances(draw: st.DrawFn) -> tuple[Instance, float | None]:
    n_robots = draw(st.integers(2, 4))
    n_tasks = draw(st.integers(1, 4 if n_robots < 4 else 2))
    percent = st.integers(0, 100).map(lambda x: x / 100)
    robots = []
    for i in range(n_robots):
        skills = draw(
            st.one_of(
                st.none(), st.lists(st.sampled_from(FEATURES), min_size=1, max_size=2, unique=True)
            )
        )
        robots.append(
            Robot(
                f"r{i}",
                {f: draw(percent) for f in FEATURES},
                skills=None if skills is None else tuple(skills),
            )
        )
    tasks = []
    for t in range(n_tasks):
        features = tuple(
            draw(st.lists(st.sampled_from(FEATURES), min_size=1, max_size=2, unique=True))
        )
        team = None
        if draw(st.booleans()):
            team = {f: draw(st.integers(1, 2)) for f in features}
        tasks.append(Task(id=t, name=f"t{t}", features=features, team=team))
    cap = draw(st.one_of(st.none(), st.integers(0, 2), st.just(0.5)))
    try:
        return Instance(tasks=tuple(tasks), robots=tuple(robots)), cap
    except DomainError:
        reject()


def _check_plan(problem: Problem, name: str) -> tuple[float, int]:
    instance = problem.instance
    solution = get_solver(name).solve(problem)
    a, teams = solution.assignment, solution.teams
    for t, task in enumerate(instance.tasks):
        if task.team is None:
            assert t not in teams and instance.eligible[t, a[t]], name
            continue
        members = teams[t]
        units = instance.units[t]
        assert len(members) == len(units) == len(set(members)), name  # distinct, covered
        assert members[0] == a[t], name  # `robot` is the first unit's member
        assert all(_covers(instance.robots[r], f) for r, f in zip(members, units, strict=True))
    loads = workload(a, instance.n_robots, teams)
    assert problem.cap.respected_by(loads), name
    n = instance.n_units
    return expected_success(instance, a, teams), sum(abs(len(loads) * x - n) for x in loads)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(team_instances())
def test_exact_solvers_equal_an_exhaustive_search_on_team_instances(
    case: tuple[Instance, float | None],
) -> None:
    instance, cap = case
    event("with teams" if instance.has_teams else "no team task")
    mode = Mode.SUCCESS_FOCUSED if cap is None else Mode.BALANCED
    reference = exhaustive(instance, cap)
    try:
        problem = Problem.build(instance, mode, cap)
        results = {name: _check_plan(problem, name) for name in EXACT}
    except InfeasibleCapError:
        event("infeasible")
        assert reference is None
        return
    assert reference is not None, "the solvers found a plan the exhaustive search did not"
    best_es = float(reference[0]) / instance.n_tasks
    for name, (es, dev) in results.items():
        assert es == pytest.approx(best_es, abs=1e-9), name
        assert dev == reference[1], f"{name} breaks the deviation tie-break"
    greedy_es, _ = _check_plan(problem, "greedy")  # valid teams, the cap held
    assert greedy_es <= best_es + 1e-9


def _team_instance() -> Instance:
    return Instance(
        tasks=(
            Task("beam", "Lift beam", ("heavy",), team={"heavy": 2}),
            Task("panel", "Fix panel", ("heavy", "careful"), team={"heavy": 1, "careful": 1}),
            Task("sweep", "Sweep", ("careful",)),
        ),
        robots=(
            Robot("crane", {"heavy": 0.9, "careful": 0.2}, skills=("heavy",)),
            Robot("arm", {"heavy": 0.3, "careful": 0.95}),
            Robot("lifter", {"heavy": 0.8, "careful": 0.4}),
        ),
    )


def test_success_load_and_w_count_units() -> None:
    instance = _team_instance()
    assert instance.n_units == 5 and instance.target_load == pytest.approx(5 / 3)
    teams = {0: (0, 2), 1: (2, 1)}
    metrics = compute_metrics(instance, [0, 2, 1], teams=teams, trials=10)
    assert metrics.workload == {"crane": 1, "arm": 2, "lifter": 2}
    # beam: mean(0.9, 0.8); panel: mean(0.8 heavy by lifter, 0.95 careful by arm); sweep 0.95
    assert metrics.expected_success == pytest.approx((0.85 + 0.875 + 0.95) / 3)
    problem = Problem.build(instance, Mode.BALANCED)
    assert problem.cap.n_tasks == 5  # the cap's W is units / robots


def test_the_answer_names_the_first_units_member_as_robot() -> None:
    problem = Problem.build(_team_instance(), Mode.SUCCESS_FOCUSED)
    solution = get_solver("optimal").solve(problem)
    assert solution.teams[0] == (0, 2)  # crane and lifter carry the beam
    assert solution.assignment[1] == solution.teams[1][0]


@pytest.mark.parametrize("name", ["q_learning", "dqn"])
def test_one_robot_methods_refuse_a_team_instance_with_a_sentence(name: str) -> None:
    with pytest.raises(DomainError) as err:
        get_solver(name).solve(Problem.build(_team_instance(), Mode.BALANCED))
    assert err.value.field == "tasks.0.team"
    assert "'optimal'" in err.value.message and name in err.value.message


def test_the_ltaa_graph_offers_and_the_rules_reasoner_picks_only_eligible_robots() -> None:
    # The crane is the best at heavy work, but only the lifter may take single heavy tasks
    # if the crane's skills lack careful; the graph's candidate list must leave it out.
    instance = Instance(
        tasks=tuple(Task(k, f"t{k}", ("heavy", "careful")) for k in range(4)),
        robots=(
            Robot("crane", {"heavy": 0.99, "careful": 0.9}, skills=("heavy",)),
            Robot("lifter", {"heavy": 0.5, "careful": 0.5}),
            Robot("arm", {"heavy": 0.4, "careful": 0.6}),
        ),
    )
    problem = Problem.build(instance, Mode.SUCCESS_FOCUSED)
    assert problem.feasible_robots(0, [0, 0, 0], 3) == [1, 2]
    solution = get_solver("ltaa").solve(problem)
    assert 0 not in solution.assignment


@pytest.mark.parametrize("name", ["greedy", "q_learning", "dqn", "ltaa"])
def test_one_task_at_a_time_methods_never_walk_into_an_unfinishable_queue(name: str) -> None:
    # W = 1, cap 0: one task each. b is better at the first task, but only b may take the
    # second, so a method that gave b the first could not finish: it must offer only a.
    instance = Instance(
        tasks=(Task(0, "lift", ("heavy",)), Task(1, "inspect", ("careful",))),
        robots=(
            Robot("a", {"heavy": 0.5, "careful": 0.9}, skills=("heavy",)),
            Robot("b", {"heavy": 0.9, "careful": 0.9}),
        ),
    )
    problem = Problem.build(instance, Mode.BALANCED, 0)
    assert problem.feasible_robots(0, [0, 0], 1) == [0]
    options = {"q_learning": {"episodes": 50}, "dqn": {"timesteps": 200}}.get(name)
    assert get_solver(name).solve(problem, options=options).assignment == [0, 1]


@pytest.mark.parametrize("guidance", [None, "optimizer"])
def test_ltaa_regret_and_guidance_respect_skills(guidance: str | None) -> None:
    # Regret is measured against the optimum of the restricted problem, so it is never
    # negative and sums to optimal's ES minus the run's; guidance reaches that optimum.
    instance = Instance(
        tasks=tuple(Task(k, f"t{k}", (FEATURES[k % 2],)) for k in range(6)),
        robots=(
            Robot("a", {"heavy": 0.6, "careful": 0.99}, skills=("heavy",)),
            Robot("b", {"heavy": 0.6, "careful": 0.7}),
            Robot("c", {"heavy": 0.5, "careful": 0.8}, skills=("careful",)),
        ),
    )
    problem = Problem.build(instance, Mode.BALANCED)
    best = get_solver("optimal").solve(problem).assignment
    solution = get_solver("ltaa").solve(problem, options={"guidance": guidance})
    assert all(instance.eligible[t, r] for t, r in enumerate(solution.assignment))
    regrets = [d["regret"] for d in solution.details["decisions"]]
    assert min(regrets) >= -1e-12
    gap = expected_success(instance, best) - expected_success(instance, solution.assignment)
    assert sum(regrets) == pytest.approx(gap, abs=1e-9)
    if guidance:
        assert gap == pytest.approx(0, abs=1e-12)
