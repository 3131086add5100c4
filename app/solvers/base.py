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
    """One robot index per task, in queue order; a team task's is the member covering its
    first unit, and `teams` lists every member (docs/allocation.md#teams)."""

    assignment: list[int]
    usage: Usage = field(default_factory=Usage)
    details: dict[str, Any] = field(default_factory=dict)
    teams: dict[int, tuple[int, ...]] = field(default_factory=dict)  # task -> robot per unit


class SolverOptions(BaseModel):
    """Per-solver `options`; unknown keys are rejected so typos do not pass silently."""

    model_config = ConfigDict(extra="forbid")


# The methods that plan team tasks (docs/allocation.md#teams); the others refuse them.
TEAM_METHODS = ("optimal", "dp", "brute_force", "greedy", "schedule", "ltaa")
# Each plans them timed and untimed: the exact scheduler itself, the LTAA graph on its own
# time lines, the others' team assignments timed by the shared list scheduler.


class Solver(ABC):
    info: ClassVar[SolverInfo]
    Options: ClassVar[type[SolverOptions]] = SolverOptions
    forms_teams: ClassVar[bool] = False  # can it plan tasks with a `team`?

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
        self.check_supported(problem)
        solution = self._solve(problem, seed=seed, options=self.parse_options(options))
        # Methods decide the free tasks; a pinned team is the answer's team as it was pinned.
        solution.teams = {**problem.pinned_teams, **solution.teams}
        if problem.instance.timed:  # untimed answers are exactly what they always were
            attach_schedule(problem, solution.assignment, solution.details, solution.teams)
        return solution

    def check_supported(self, problem: Problem) -> None:
        """Refuse, with a sentence naming the field and the methods to use, an instance this
        method cannot plan (docs/allocation.md#teams)."""
        instance = problem.instance
        if not instance.has_teams:
            return
        t = next(i for i, task in enumerate(instance.tasks) if task.team is not None)
        task = instance.tasks[t]
        if not self.forms_teams:
            raise DomainError(
                f"tasks.{t}.team",
                f"task {task.id!r} needs a team, and solver '{self.info.name}' plans one robot "
                f"per task; use {_listed(TEAM_METHODS)} for team tasks "
                "(docs/allocation.md#teams)",
                code="unsupported_field",
            )

    @abstractmethod
    def _solve(self, problem: Problem, *, seed: int, options: Any) -> Solution: ...


SolverFactory = Callable[[], Solver]


def _listed(names: tuple[str, ...]) -> str:
    quoted = [f"'{n}'" for n in names]
    return ", ".join(quoted[:-1]) + f" or {quoted[-1]}"
