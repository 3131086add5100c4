"""The one contract every allocation method meets, and its registry."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, ValidationError

from app.domain.errors import DomainError
from app.domain.problem import Problem
from app.domain.usage import Usage
from app.reasoners.factory import ReasonerSettings
from app.solvers.timed import attach_schedule


@dataclass(frozen=True)
class SolverInfo:
    name: str
    description: str
    exact: bool
    limits: str


@dataclass
class Solution:
    """One robot index per task, in queue order."""

    assignment: list[int]
    usage: Usage = field(default_factory=Usage)
    details: dict[str, Any] = field(default_factory=dict)


class SolverOptions(BaseModel):
    """Per-solver `options`; unknown keys are rejected so typos do not pass silently."""

    model_config = ConfigDict(extra="forbid")


class Solver(ABC):
    info: ClassVar[SolverInfo]
    Options: ClassVar[type[SolverOptions]] = SolverOptions

    def __init__(self, *, settings: ReasonerSettings | None = None) -> None:
        # The server's settings, for methods that call out (the `ltaa` reasoners); the
        # exact and learning solvers never read them.
        self.settings = settings

    def parse_options(self, options: Mapping[str, Any] | None) -> SolverOptions:
        try:
            return self.Options.model_validate(dict(options or {}))
        except ValidationError as exc:
            err = exc.errors()[0]
            where = ".".join(str(p) for p in err["loc"])
            raise DomainError(
                f"options.{where}" if where else "options",
                f"{err['msg']} (solver '{self.info.name}' accepts: "
                f"{', '.join(self.Options.model_fields) or 'no options'})",
            ) from None

    def solve(
        self, problem: Problem, *, seed: int = 0, options: Mapping[str, Any] | None = None
    ) -> Solution:
        solution = self._solve(problem, seed=seed, options=self.parse_options(options))
        if problem.instance.timed:  # untimed answers are exactly what they always were
            attach_schedule(problem, solution.assignment, solution.details)
        return solution

    @abstractmethod
    def _solve(self, problem: Problem, *, seed: int, options: Any) -> Solution: ...


SolverFactory = Callable[[], Solver]
