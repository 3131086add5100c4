"""Per-decision regret and optimizer guidance (beyond the paper)."""

from __future__ import annotations

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
