"""The reinforcement-learning baselines: real training, seeded, cap-respecting, near-optimal."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.domain.catalog import scenario, teach_tasks
from app.domain.errors import DomainError, InfeasibleCapError, TooLargeError
from app.domain.metrics import expected_success, workload
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.solvers.registry import get_solver

ROOT = Path(__file__).resolve().parents[2]
FAST = {"q_learning": {"episodes": 3_000}, "dqn": {"timesteps": 2_000}}
FEATURES = ("heavy", "dexterous", "careful")


def small_instance(n_tasks: int = 9) -> Instance:
    return Instance(tasks=teach_tasks()[:n_tasks], robots=scenario("baseline").instance.robots)


def baseline_optimum(problem: Problem) -> float:
    return expected_success(problem.instance, get_solver("optimal").solve(problem).assignment)


@pytest.mark.parametrize("name", ["q_learning", "dqn"])
def test_same_seed_gives_same_allocation(name: str) -> None:
    problem = Problem.build(small_instance(), Mode.BALANCED)
    solver = get_solver(name)
    first = solver.solve(problem, seed=11, options=FAST[name]).assignment
    again = solver.solve(problem, seed=11, options=FAST[name]).assignment
    assert first == again
    assert len(first) == problem.instance.n_tasks


@pytest.mark.parametrize("name", ["q_learning", "dqn"])
@pytest.mark.parametrize(
    ("n_tasks", "mode", "max_deviation"),
    [
        (9, Mode.BALANCED, None),  # loads in [2, 4]
        (9, Mode.AGGRESSIVE_BALANCE, 0),  # exactly 3 each: most late choices are forced
        (10, Mode.BALANCED, 1),  # fractional W = 10/3: loads in [3, 4]
        (12, Mode.SUCCESS_FOCUSED, None),  # no cap at all
    ],
)
def test_allocation_respects_cap(
    name: str, n_tasks: int, mode: Mode, max_deviation: float | None
) -> None:
    problem = Problem.build(small_instance(n_tasks), mode, max_deviation)
    # Barely trained on purpose: masking, not learning, must keep the cap.
    options = {"q_learning": {"episodes": 5}, "dqn": {"timesteps": 100}}[name]
    assignment = get_solver(name).solve(problem, seed=3, options=options).assignment
    loads = workload(assignment, problem.instance.n_robots)
    assert len(assignment) == n_tasks
    assert problem.cap.respected_by(loads), loads


@st.composite
def capped_problems(draw: st.DrawFn) -> Problem:
    n_robots = draw(st.integers(1, 4))
    n_tasks = draw(st.integers(1, 10))
    rate = st.integers(0, 100).map(lambda x: x / 100)
    robots = tuple(
        Robot(name=f"r{i}", success={f: draw(rate) for f in FEATURES}) for i in range(n_robots)
    )
    tasks = tuple(
        Task(id=t, name=f"t{t}", features=(draw(st.sampled_from(FEATURES)),))
        for t in range(n_tasks)
    )
    cap = draw(st.sampled_from([0, 0.5, 1, 2, 3.5]))
    try:
        return Problem.build(Instance(tasks=tasks, robots=robots), Mode.BALANCED, cap)
    except InfeasibleCapError:
        return Problem.build(Instance(tasks=tasks, robots=robots), Mode.SUCCESS_FOCUSED)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(capped_problems(), st.integers(0, 2**31 - 1))
def test_q_learning_respects_cap_on_random_instances(problem: Problem, seed: int) -> None:
    assignment = get_solver("q_learning").solve(problem, seed=seed, options={"episodes": 50})
    loads = workload(assignment.assignment, problem.instance.n_robots)
    assert problem.cap.respected_by(loads)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["q_learning", "dqn"])
def test_default_options_within_three_points_of_optimal(name: str) -> None:
    problem = Problem.build(scenario("baseline").instance, Mode.BALANCED)
    assert (problem.cap.lower, problem.cap.upper) == (8, 16)
    optimum = baseline_optimum(problem)
    assert optimum == pytest.approx(0.786111, abs=1e-6)
    assignment = get_solver(name).solve(problem, seed=0).assignment
    assert problem.cap.respected_by(workload(assignment, problem.instance.n_robots))
    assert expected_success(problem.instance, assignment) >= optimum - 0.03


@pytest.mark.parametrize("name", ["q_learning", "dqn"])
def test_unknown_option_names_the_field(name: str) -> None:
    problem = Problem.build(small_instance(), Mode.BALANCED)
    with pytest.raises(DomainError) as err:
        get_solver(name).solve(problem, options={"episodez": 10})
    assert err.value.field.startswith("options.")
    assert "episodez" in err.value.field


@pytest.mark.parametrize(
    ("name", "options", "field"),
    [
        ("q_learning", {"episodes": 0}, "options.episodes"),
        ("q_learning", {"episodes": 10**9}, "options.episodes"),
        ("q_learning", {"epsilon_end": 1.5}, "options.epsilon_end"),
        ("dqn", {"timesteps": 5}, "options.timesteps"),
        ("dqn", {"gamma": 2}, "options.gamma"),
    ],
)
def test_out_of_range_option_names_the_field(
    name: str, options: dict[str, float], field: str
) -> None:
    problem = Problem.build(small_instance(), Mode.BALANCED)
    with pytest.raises(DomainError) as err:
        get_solver(name).solve(problem, options=options)
    assert err.value.field == field


def test_q_learning_refuses_an_oversized_table() -> None:
    robots = scenario("baseline").instance.robots
    tasks = tuple(Task(id=i, name=f"t{i}", features=("heavy",)) for i in range(200))
    problem = Problem.build(Instance(tasks=tasks, robots=robots), Mode.BALANCED)
    with pytest.raises(TooLargeError) as err:
        get_solver("q_learning").solve(problem)
    assert err.value.field == "tasks"
    assert "200 tasks" in err.value.message
    assert "200,000" in err.value.message


def test_rl_solvers_say_they_are_approximate() -> None:
    for name in ("q_learning", "dqn"):
        info = get_solver(name).info
        assert info.exact is False
        assert "approximate" in info.description


def _run_python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_listing_solvers_does_not_load_torch() -> None:
    result = _run_python(
        """
        import sys
        from app.solvers.registry import get_solver, solver_names
        for name in solver_names():
            get_solver(name).info
        loaded = [m for m in ("torch", "stable_baselines3", "gymnasium") if m in sys.modules]
        print(loaded)
        """
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def test_dqn_training_writes_nothing_to_the_temp_dir(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # SB3's default logger makes tempdir/SB3-<time> per training; a private temp dir
    # makes the check exact and safe next to other processes training in parallel.
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    assert tempfile.gettempdir() == str(tmp_path)
    problem = Problem.build(small_instance(3), Mode.SUCCESS_FOCUSED)
    get_solver("dqn").solve(problem, seed=1, options={"timesteps": 100})
    # Only SB3's own entries: torch may keep a per-user cache dir there, made once, not per call.
    assert sorted(p.name for p in tmp_path.glob("SB3-*")) == []


def test_dqn_without_torch_explains_how_to_install() -> None:
    result = _run_python(
        """
        import sys
        sys.modules["torch"] = None  # as if the rl extra were not installed
        from app.domain.catalog import scenario
        from app.domain.errors import DomainError
        from app.domain.problem import Problem
        from app.solvers.registry import get_solver
        try:
            get_solver("dqn").solve(Problem.build(scenario("baseline").instance))
        except DomainError as exc:
            print(exc.field, exc.code, exc.message, sep="|")
        """
    )
    assert result.returncode == 0, result.stderr
    field, code, message = result.stdout.strip().split("|")
    assert (field, code) == ("solver", "solver_unavailable")
    assert "pip install torch==2.13.0 && pip install -e '.[rl]'" in message


def test_environment_masks_match_the_cap_and_rewards_are_regret() -> None:
    from app.solvers.allocation_env import AllocationEnv

    problem = Problem.build(small_instance(), Mode.AGGRESSIVE_BALANCE, 0)
    s, cap = problem.instance.success, problem.cap
    env = AllocationEnv(s, cap)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    chosen: list[int] = []
    total, done = 0.0, False
    while not done:
        allowed = env.action_masks()
        t = len(chosen)
        expected = cap.feasible_robots(env.loads, s.shape[0] - t - 1)
        assert list(np.flatnonzero(allowed)) == expected
        assert list(obs[: s.shape[1]]) == list(allowed.astype(np.float32))
        robot = int(np.flatnonzero(allowed)[-1])
        chosen.append(robot)
        obs, reward, done, truncated, _ = env.step(robot)
        assert not truncated
        assert env.observation_space.contains(obs)
        total += reward
    assert total == pytest.approx(s[np.arange(len(chosen)), chosen].sum() - s.max(axis=1).sum())
    assert cap.respected_by(env.loads)


def test_environment_rejects_a_cap_breaking_robot() -> None:
    from app.solvers.allocation_env import AllocationEnv

    problem = Problem.build(small_instance(3), Mode.AGGRESSIVE_BALANCE, 0)  # one task each
    env = AllocationEnv(problem.instance.success, problem.cap)
    env.reset()
    env.step(0)
    with pytest.raises(ValueError, match="workload cap"):
        env.step(0)


def _heavy_down(n_tasks: int, pinned: int) -> Problem:
    # The first `pinned` tasks done round-robin, then the heavy robot (index 2) breaks down.
    pins = {t: t % 3 for t in range(pinned)}
    return Problem.build(small_instance(n_tasks), Mode.BALANCED, pinned=pins, unavailable=[2])


@pytest.mark.parametrize("name", ["q_learning", "dqn"])
@pytest.mark.parametrize(("n_tasks", "pinned"), [(9, 3), (12, 6), (9, 9), (10, 0)])
def test_learners_honour_pins_and_unavailable_robots(name: str, n_tasks: int, pinned: int) -> None:
    problem = _heavy_down(n_tasks, pinned)
    options = {"q_learning": {"episodes": 5}, "dqn": {"timesteps": 100}}[name]
    assignment = get_solver(name).solve(problem, seed=3, options=options).assignment
    assert {t: assignment[t] for t in problem.pinned} == dict(problem.pinned)
    assert all(assignment[t] != 2 for t in problem.free_tasks)
    assert problem.cap.respected_by(workload(assignment, 3))


@pytest.mark.parametrize("name", ["q_learning", "dqn"])
def test_learners_train_on_the_pinned_problem(name: str) -> None:
    # 6 free tasks on 2 robots: small enough that a modest training finds the optimum.
    problem = _heavy_down(12, 6)
    options = {"q_learning": {"episodes": 4_000}, "dqn": {"timesteps": 4_000}}[name]
    assignment = get_solver(name).solve(problem, seed=0, options=options).assignment
    assert expected_success(problem.instance, assignment) == pytest.approx(
        baseline_optimum(problem), abs=1e-9
    )


def test_environment_starts_from_the_pins() -> None:
    from app.solvers.allocation_env import AllocationEnv
    from app.solvers.free_part import FreePart

    part = FreePart.of(_heavy_down(12, 6))
    assert part.initial_loads == (2, 2) and part.success.shape == (6, 2)
    env = AllocationEnv(part.success, part.cap, part.initial_loads)
    env.reset()
    assert env.loads == [2, 2]
    for t in range(6):
        allowed = env.action_masks()
        assert list(np.flatnonzero(allowed)) == part.cap.feasible_robots(env.loads, 6 - t - 1)
        env.step(int(np.flatnonzero(allowed)[0]))
    assert part.cap.respected_by(env.loads) and sum(env.loads) == 10
    env.reset()
    assert env.loads == [2, 2]
