"""A run's record read a page at a time, for people looking at it (the supervisor
console): the run at a glance, one page of decisions with their attempts, one attempt's
prompts and reply.

The same tables and records the JSON API reads, with only the columns each view needs: a
10,000-task run's page must not load 10,000 reasonings, nor any prompt until asked.
"""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.orm import Session, sessionmaker

from app.audit.signoffs import SignOff, signoffs
from app.domain.errors import RunNotFoundError
from app.domain.metrics import balance_score, expected_success
from app.domain.phases import detect_phase
from app.domain.usage import Usage
from app.runs import records
from app.runs.spec import RunSpec
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.models import Attempt, Run, RunEvent


@dataclass(frozen=True)
class RunOverview:
    run: Run
    spec: RunSpec
    allocated: int
    usage: Usage
    loads: list[int]  # per robot, from the decisions so far
    balance: list[float]  # balance after each decision, in task order
    events: list[RunEvent]
    signoffs: list[SignOff]
    expected_success: float | None  # of the decisions so far (mean S), None before any
    balance_score: float | None  # of the final loads, once every task is decided

    @property
    def robots(self) -> list[str]:
        return [r["name"] for r in self.spec.instance_data["robots"]]

    @property
    def phase(self) -> str:
        n = self.run.n_tasks
        return detect_phase(min(self.allocated, n), n).value


def _require(session: Session, run_id: str) -> Run:
    run = repo.get_run(session=session, run_id=run_id)
    if run is None:
        raise RunNotFoundError(run_id)
    return run


def run_row(*, sessions: sessionmaker[Session], run_id: str) -> Run:
    """The run's row alone (RunNotFoundError if there is none)."""
    with sessions() as session:
        return _require(session, run_id)


def overview(*, sessions: sessionmaker[Session], run_id: str) -> RunOverview:
    with sessions() as session:
        run = _require(session, run_id)
        outline = decision_repo.decision_outline(session=session, run_id=run_id)
        usage = records.usage_of(decision_repo.reply_costs(session=session, run_id=run_id))
        events = repo.events(session=session, run_id=run_id)
        signed = signoffs(session=session, run_id=run_id)
    spec = RunSpec.from_json(run.request)
    instance = spec.problem.instance
    # docs/allocation.md#teams: a team decision counts once for each member, as the run's
    # workload in GET /runs/{id} does; its success is the team's mean over its units.
    index = {name: i for i, name in enumerate(r["name"] for r in spec.instance_data["robots"])}
    teams = {
        row.task_index: tuple(index[m["robot"]] for m in row.team) for row in outline if row.team
    }
    loads = [0] * instance.n_robots
    for row in outline:
        for robot in teams.get(row.task_index, (row.robot,)):
            loads[robot] += 1
    assignment = [row.robot for row in outline]
    return RunOverview(
        run=run,
        spec=spec,
        allocated=len(outline),
        usage=usage,
        loads=loads,
        balance=[row.balance_after for row in outline],
        events=events,
        signoffs=signed,
        expected_success=expected_success(instance, assignment, teams) if assignment else None,
        balance_score=balance_score(loads, instance.target_load)
        if len(outline) == run.n_tasks
        else None,
    )


class AttemptNotFoundError(LookupError):
    def __init__(self, run_id: str, task_index: int, attempt: int) -> None:
        super().__init__(f"run {run_id} has no attempt {attempt} for task index {task_index}")


def attempt_detail(
    *, sessions: sessionmaker[Session], run_id: str, task_index: int, attempt: int
) -> Attempt:
    """One attempt with its prompts and reply."""
    with sessions() as session:
        _require(session, run_id)
        row = decision_repo.get_attempt(
            session=session, run_id=run_id, task_index=task_index, attempt=attempt
        )
        if row is None:
            raise AttemptNotFoundError(run_id, task_index, attempt)
        return row
