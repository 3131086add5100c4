"""Every allocation method by name. Modules load on first use, so torch loads only for dqn."""

from __future__ import annotations

from importlib import import_module

from app.domain.errors import DomainError
from app.reasoners.factory import ReasonerSettings
from app.solvers.base import Solver

_SOLVERS: dict[str, str] = {
    "greedy": "app.solvers.greedy:GreedySolver",
    "brute_force": "app.solvers.brute_force:BruteForceSolver",
    "dp": "app.solvers.dp:DynamicProgrammingSolver",
    "optimal": "app.solvers.optimal:OptimalSolver",
    "schedule": "app.solvers.schedule:ScheduleSolver",
    "q_learning": "app.solvers.q_learning:QLearningSolver",
    "dqn": "app.solvers.dqn:DQNSolver",
    "ltaa": "app.solvers.ltaa:LTAASolver",
}


def solver_names() -> list[str]:
    return list(_SOLVERS)


def get_solver(name: str, *, settings: ReasonerSettings | None = None) -> Solver:
    target = _SOLVERS.get(name)
    if target is None:
        raise DomainError(
            "solver",
            f"unknown solver '{name}'; choose one of: {', '.join(_SOLVERS)}",
            code="unknown_solver",
        )
    module, cls = target.split(":")
    solver_cls: type[Solver] = getattr(import_module(module), cls)
    return solver_cls(settings=settings)


def register(name: str, target: str) -> None:
    """Add a method (the LTAA graph registers itself this way)."""
    _SOLVERS[name] = target
