"""The `ltaa` entry of /allocate, through the solver registry."""

from __future__ import annotations

import pytest

from app.domain.errors import DomainError
from app.domain.metrics import workload
from app.domain.modes import Mode
from app.solvers.registry import get_solver, solver_names
from tests.support.ltaa_support import problem, run


def test_registered_and_runs_the_graph_with_rules_by_default() -> None:
    assert "ltaa" in solver_names()
    solver = get_solver("ltaa")
    prob = problem("medium_excels", Mode.AGGRESSIVE_BALANCE)
    solution = solver.solve(prob)
    rec, _ = run(prob)
    assert solution.assignment == [d.robot for d in rec.decisions()]
    assert prob.cap.respected_by(workload(solution.assignment, 3))
    assert (solution.usage.llm_calls, solution.usage.input_tokens) == (0, 0)
    details = solution.details
    assert details["reasoner"] == "rules" and details["fallbacks"] == 0
    assert details["mean_quality"] >= 0.9 and len(details["decisions"]) == 36
    assert set(details["decisions"][0]) == {
        "task_index",
        "robot",
        "phase",
        "quality",
        "attempts",
        "fallback",
        "confidence",
        "regret",
    }


def test_options_reach_the_graph() -> None:
    solution = get_solver("ltaa").solve(
        problem(n_tasks=3), options={"quality_threshold": 0.95, "max_retries": 0}
    )
    assert solution.details["fallbacks"] == 0  # the rules answers score 1.0


@pytest.mark.parametrize(
    ("options", "field", "message"),
    [
        ({"reasoner": "gpt"}, "options.reasoner", "unknown reasoner 'gpt'"),
        ({"reasoner": "anthropic"}, "options.reasoner", "ANTHROPIC_API_KEY"),
        ({"max_retries": -1}, "options.max_retries", "greater than or equal to 0"),
        ({"quality_threshold": 2}, "options.quality_threshold", "less than or equal to 1"),
        ({"temprature": 0.1}, "options.temprature", "Extra inputs are not permitted"),
    ],
)
def test_bad_options_are_domain_errors(
    options: dict, field: str, message: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    for var in ("ANTHROPIC_API_KEY", "LTAA_ANTHROPIC_API_KEY"):
        monkeypatch.delenv(var, raising=False)
    with pytest.raises(DomainError) as err:
        get_solver("ltaa").solve(problem(n_tasks=2), options=options)
    assert err.value.field == field and message in err.value.message
