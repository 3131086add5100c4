"""Optimizer guidance on a timed instance (SPEC 16 "The LTAA graph on time", SPEC 4): the
`schedule` solver's plan for the tasks still to decide.

The time-free oracle (app.solvers.oracle) counts the tasks after the current one in queue
order; a timed run decides in time order and its best completion depends on when each
robot is free. So the guidance here is CP-SAT's schedule of the remaining problem: every
task decided so far pinned to its robot at its recorded start (a fact, as a revision's
started tasks are), the rest free. It is solved when first asked, and again only when the
run departs from it (a reasoner that overrules the guidance, a review): while the run
follows the plan, the plan's remaining part stays the best known completion.

CP-SAT stops at a wall-clock limit, so two solves of one problem may return different
plans of equal or near value: a guided timed run that is resumed after a crash solves
again and may be guided differently from there on (docs/schedules.md, "Runs in time").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from app.domain.errors import DomainError
from app.domain.problem import Problem
from app.graph.recorder import DecisionRecord, Recorder
from app.solvers.cpsat.search import solve_schedule

GUIDANCE_TIME_LIMIT_S = 5.0


class ScheduleGuidance:
    def __init__(
        self,
        problem: Problem,
        recorder: Recorder,
        *,
        time_limit_s: float = GUIDANCE_TIME_LIMIT_S,
    ) -> None:
        self._problem = problem
        self._recorder = recorder
        self._time_limit_s = time_limit_s
        self._plan: dict[int, int] | None = None
        self.solves = 0

    def __call__(self, task_index: int, loads: Sequence[int]) -> int | None:
        decided = {d.task_index: d for d in self._recorder.decisions() if d.start is not None}
        plan = self._plan
        if plan is None or any(plan.get(t) != d.robot for t, d in decided.items()):
            plan = self._plan = self._solve(decided)
        return plan.get(task_index)

    def _solve(self, decided: Mapping[int, DecisionRecord]) -> dict[int, int]:
        problem = self._problem
        self.solves += 1
        try:
            rest = Problem.build(
                problem.instance,
                problem.mode,
                problem.cap.max_deviation,
                uncapped=problem.cap.max_deviation is None,
                pinned={**problem.pinned, **{t: d.robot for t, d in decided.items()}},
                unavailable=problem.unavailable,
                objective=problem.objective,
                pinned_starts={
                    **problem.pinned_starts,
                    **{t: d.start for t, d in decided.items() if d.start is not None},
                },
                not_before=problem.not_before,
            )
            outcome = solve_schedule(rest, time_limit_s=self._time_limit_s, workers=1)
        except DomainError:
            # No schedule of the rest exists (or none was found in time): no guidance, the
            # graph decides by its own rule.
            return {}
        return dict(enumerate(outcome.schedule.assignment))
