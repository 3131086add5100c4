"""Per-decision regret and optimizer guidance (beyond the paper)."""

from __future__ import annotations

from typing import Any

import pytest

from app.domain.catalog import scenarios
from app.domain.metrics import expected_success
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.solvers.oracle import CompletionOracle
from app.solvers.registry import get_solver

CASES = [(name, mode) for name in scenarios() for mode in Mode]


def _optimum(problem: Problem) -> float:
    return expected_success(problem.instance, get_solver("optimal").solve(problem).assignment)


@pytest.mark.parametrize(("scenario", "mode"), CASES)
def test_regrets_sum_to_the_gap_to_optimal(scenario: str, mode: Mode) -> None:
    problem = Problem.build(scenarios()[scenario].instance, mode)
    solution = get_solver("ltaa").solve(problem)
    regrets = [d["regret"] for d in solution.details["decisions"]]
    assert all(r is not None and r >= -1e-12 for r in regrets)
    gap = _optimum(problem) - expected_success(problem.instance, solution.assignment)
    assert sum(regrets) == pytest.approx(gap, abs=1e-9)


@pytest.mark.parametrize(("scenario", "mode"), CASES)
def test_guided_rules_ltaa_has_zero_regret(scenario: str, mode: Mode) -> None:
    problem = Problem.build(scenarios()[scenario].instance, mode)
    solution = get_solver("ltaa").solve(problem, options={"guidance": "optimizer"})
    assert solution.details["regret"] == pytest.approx(0.0, abs=1e-9)
    assert expected_success(problem.instance, solution.assignment) == pytest.approx(
        _optimum(problem), abs=1e-9
    )
    assert solution.details["fallbacks"] == 0


def test_unguided_rules_ltaa_gives_something_away_somewhere() -> None:
    # The paper's rule is not an optimiser: on baseline/aggressive_balance it loses ~2 points.
    problem = Problem.build(scenarios()["baseline"].instance, Mode.AGGRESSIVE_BALANCE)
    solution = get_solver("ltaa").solve(problem)
    assert solution.details["regret"] > 0.01


def test_oracle_guidance_costs_name_the_free_choice() -> None:
    problem = Problem.build(scenarios()["baseline"].instance, Mode.BALANCED)
    oracle = CompletionOracle(problem)
    choice = oracle.guidance(0, [0, 0, 0])
    assert choice is not None
    assert choice.costs[choice.robot] == pytest.approx(0.0, abs=1e-6)
    assert all(c is None or c >= 0 for c in choice.costs)
    # Loads at the cap's upper bound make that robot unavailable.
    late = oracle.guidance(30, [16, 8, 6])
    assert late is not None and late.costs[0] is None


def test_guided_prompt_carries_the_choice_and_the_costs() -> None:
    from app.graph.context import decision_context
    from app.graph.prompts import user_prompt
    from app.graph.state import initial_state, task_view

    problem = Problem.build(scenarios()["baseline"].instance, Mode.BALANCED)
    choice = CompletionOracle(problem).guidance(0, [0, 0, 0])
    assert choice is not None
    state = initial_state(problem)
    state["view"] = task_view(problem, 0, [0, 0, 0], choice.robot, choice.costs)
    text = user_prompt(decision_context(problem, state))
    assert "Optimizer guidance:" in text and "Success points each choice gives away" in text


def _pinned_problem(mode: Mode) -> Problem:
    # Heavy breaks down after task 17, having taken every third task; light also took task 20.
    pins = {t: t % 3 for t in range(18)} | {20: 0}
    return Problem.build(scenarios()["baseline"].instance, mode, pinned=pins, unavailable=[2])


def _walk(problem: Problem, oracle: CompletionOracle, pick: Any) -> tuple[list[int], float]:
    """Decide the queue in order as the graph does: pins take their robot and are already
    in the loads (initial_loads); free tasks add to the loads."""
    loads, assignment, regret = list(problem.initial_loads), [], 0.0
    for t in range(problem.instance.n_tasks):
        robot = pick(t, loads)
        regret += oracle.regret(t, loads, robot)
        if t not in problem.pinned:
            loads[robot] += 1
        assignment.append(robot)
    return assignment, regret


@pytest.mark.parametrize("mode", list(Mode))
def test_the_oracle_answers_on_the_pinned_problem(mode: Mode) -> None:
    problem = _pinned_problem(mode)
    oracle = CompletionOracle(problem)
    best = _optimum(problem)

    def guided(t: int, loads: list[int]) -> int:
        choice = oracle.guidance(t, loads)
        assert choice is not None
        if t in problem.pinned:  # a pin is the only choice, also on the unavailable robot
            assert choice.robot == problem.pinned[t] and choice.costs[choice.robot] == 0.0
            assert sum(c is not None for c in choice.costs) == 1
        else:
            assert choice.costs[2] is None  # the unavailable robot takes no new task
        return choice.robot

    assignment, regret = _walk(problem, oracle, guided)
    assert regret == pytest.approx(0.0, abs=1e-12)
    assert expected_success(problem.instance, assignment) == pytest.approx(best, abs=1e-12)
    assert oracle.value(0, problem.initial_loads) == pytest.approx(
        best * 36 - sum(problem.instance.success[t, r] for t, r in problem.pinned.items())
    )
    # Regrets of any allocation that honours the pins telescope to its gap to the optimum.
    greedy = get_solver("greedy").solve(problem).assignment
    _, greedy_regret = _walk(problem, oracle, lambda t, _loads: greedy[t])
    gap = best - expected_success(problem.instance, greedy)
    assert greedy_regret == pytest.approx(gap, abs=1e-12)
    # Moving a pinned task or using the unavailable robot is no choice at all.
    assert oracle.loss(0, problem.initial_loads, 1) is None
    assert oracle.loss(18, problem.initial_loads, 2) is None
