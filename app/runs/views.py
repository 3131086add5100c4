"""A run read back for clients and supervisors: its status with one page of its decisions (the
totals cover every decision, so a long run answers a poll without sending them all), its
trace, and the listings. Read-only: the commands that change a run are app.runs.service."""

from __future__ import annotations

import statistics
from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session, defer, sessionmaker

from app.audit.signoffs import SignOff, signoffs
from app.domain.errors import StateConflictError
from app.domain.metrics import Metrics, compute_metrics
from app.domain.phases import detect_phase
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.progress import TimedProgress
from app.domain.scheduling.schedule import Schedule, build_schedule
from app.domain.usage import Usage
from app.graph.recorder import DecisionRecord
from app.graph.timing import decision_teams
from app.runs import records
from app.runs.lifecycle import RunStatus
from app.runs.spec import LruCache, RunSpec
from app.schedule_views import violations_json
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store import run_totals
from app.store.models import Attempt, ExecutionReport, Run, RunEvent
from app.store.tombstones import missing_run

# Parsed once per process: a poll of a 10,000-task run re-parsed its 1 MB request each time.
_SPECS: LruCache[RunSpec] = LruCache(64)
_METRICS: LruCache[Metrics] = LruCache(256)
# A completed timed run's plan in time, rebuilt from its decisions (which never change).
_PLANS: LruCache[tuple[Problem, Schedule]] = LruCache(64)


def require_run(session: Session, run_id: str, *, lock: bool = False) -> Run:
    """The run, or the error a missing id answers (410 for an archived one, else 404)."""
    run = repo.get_run(session=session, run_id=run_id, for_update=lock)
    if run is None:
        raise missing_run(session, run_id)
    return run


@dataclass
class RunView:
    """A run with one page of its decisions; the totals (progress, workload, regret, metrics)
    cover every decision, so a long run answers a poll without sending them all."""

    run: Run
    spec: RunSpec
    decisions: list[DecisionRecord]  # the page's, but those the caller said it has
    offset: int
    allocated: int
    workload: dict[str, int]
    regret: float | None
    usage: Usage
    metrics: Metrics | None
    signoffs: list[SignOff] = field(default_factory=list)
    execution: dict[int, ExecutionReport] = field(default_factory=dict)
    # Task index -> the parent decision's chain hash, for this page's pinned decisions.
    pins: dict[int, str | None] = field(default_factory=dict)
    # The task indexes of the page, in order (those in `decisions` and those skipped).
    page: list[int] = field(default_factory=list)
    # A completed timed run's: the rules its plan breaks (app.schedule_views.violations_json).
    violations: list[dict[str, Any]] | None = None

    @property
    def progress(self) -> dict[str, Any]:
        return {
            "allocated": self.allocated,
            "total": self.run.n_tasks,
            "phase": detect_phase(min(self.allocated, self.run.n_tasks), self.run.n_tasks).value,
        }


def run_view(
    *,
    sessions: sessionmaker[Session],
    run_id: str,
    offset: int = 0,
    limit: int | None = None,
    have: Collection[int] = (),
    tallies: LruCache[run_totals.Tally] | None = None,
) -> RunView:
    """The run with its decisions from the offset-th, at most limit of them (None: all).

    `have`: task indexes whose decision the caller keeps from an earlier read (a stored
    decision never changes): those are left out of `decisions` unless they have an
    execution report, the one part of a page row that moves. `tallies`: the settled
    totals of the runs this caller polls (app.store.run_totals.Tally), so that a poll reads
    only what was stored since the last (aggregated in SQL, the whole run's rows are read
    with their text: 30 ms a poll of a 10,000-task run); None: aggregated in SQL."""
    with sessions() as session:
        # The request (a 10,000-task instance is a megabyte of JSON) is read and parsed once
        # per run: it never changes, and a poll every 0.5 s parsed it every time.
        run = session.scalar(select(Run).options(defer(Run.request)).where(Run.id == run_id))
        if run is None:
            raise missing_run(session, run_id)
        spec = _SPECS.get_or_load(
            run_id, lambda: RunSpec.from_json(require_run(session, run_id).request)
        )
        if tallies is None:
            totals = run_totals.decision_totals(session=session, run_id=run_id)
            replies = run_totals.reply_totals(session=session, run_id=run_id)
        else:
            now, settled = run_totals.tally(
                session=session, run_id=run_id, settled=tallies.get(run_id) or run_totals.Tally()
            )
            tallies.put(run_id, settled)
            totals, replies = now.totals(), now.reply_rows()
        execution = {
            r.task_index: r for r in repo.execution_reports(session=session, run_id=run_id)
        }
        complete = run.status == RunStatus.COMPLETED and totals.allocated == run.n_tasks
        # A completed timed revision's pins without times are shown where it placed them: read
        # afresh, not as kept from a poll made before the revision had placed them.
        unplaced = (
            run_totals.unplaced_pins(session=session, run_id=run_id)
            if complete and spec.problem.instance.timed
            else set()
        )
        if have:
            page = run_totals.page_indexes(
                session=session, run_id=run_id, offset=offset, limit=limit
            )
            wanted = [t for t in page if t not in have or t in execution or t in unplaced]
            rows = run_totals.decision_rows(session=session, run_id=run_id, tasks=wanted)
        else:
            rows = run_totals.decision_page(
                session=session, run_id=run_id, offset=offset, limit=limit
            )
            page = [d.task_index for d in rows]
        decisions = [records.decision_record(d) for d in rows]
        pins = pins_of(rows)
        usage = records.usage_of_totals(replies)
        signed = signoffs(session=session, run_id=run_id)
        completed = complete
        teams = _teams(session, run_id, spec)
        # Every decision's robot only once the run is complete, for its metrics.
        outcomes = (
            decision_repo.decision_outcomes(session=session, run_id=run_id)
            if completed and _METRICS.get(run_id) is None
            else []
        )
    names = [r["name"] for r in spec.instance_data["robots"]]
    workload = _workload(names, totals.by_robot, teams)
    metrics = _completed_metrics(run_id, spec, names, outcomes) if completed else None
    violations = None
    if complete and spec.problem.instance.timed:
        violations, decisions = _timed_reading(sessions, run_id, decisions, unplaced)
    return RunView(
        run=run,
        spec=spec,
        decisions=decisions,
        offset=offset,
        allocated=totals.allocated,
        workload=workload,
        regret=totals.regret,
        usage=usage,
        metrics=metrics,
        execution=execution,
        pins=pins,
        signoffs=signed,
        page=page,
        violations=violations,
    )


def _completed_metrics(
    run_id: str, spec: RunSpec, names: list[str], outcomes: Sequence[Any]
) -> Metrics:
    """A completed run's metrics, computed once from every decision's robot (its decisions
    never change, so they are kept)."""
    metrics = _METRICS.get(run_id)
    if metrics is not None:
        return metrics
    problem = spec.problem
    index = {name: i for i, name in enumerate(names)}
    metrics = compute_metrics(
        problem.instance,
        [o.robot for o in outcomes],
        seed=spec.seed,
        scope=problem.balance_scope,
        teams={o.task_index: tuple(index[m["robot"]] for m in o.team) for o in outcomes if o.team},
    )
    if problem.pinned:
        # A pin keeps the success it was decided with, whatever set_rates changed.
        metrics = replace(
            metrics, expected_success=statistics.fmean(o.expected_success for o in outcomes)
        )
    _METRICS.put(run_id, metrics)
    return metrics


def _teams(session: Session, run_id: str, spec: RunSpec) -> list[Any]:
    """The members of each decision (None: one robot), read only on an instance with team
    tasks (docs/allocation.md#teams), where a decision counts for each member."""
    if not any(t.get("team") for t in spec.instance_data["tasks"]):
        return []
    return [o.team for o in decision_repo.decision_outcomes(session=session, run_id=run_id)]


def _workload(
    names: list[str], by_robot: dict[int, int], teams: list[list[dict[str, str]] | None]
) -> dict[str, int]:
    """Decisions per robot, a team decision once for each member (docs/allocation.md#teams)."""
    workload = dict.fromkeys(names, 0)
    for robot, n in sorted(by_robot.items()):
        workload[names[robot]] += n
    for team in teams:  # the first member is the decision's robot, counted above
        for member in (team or [])[1:]:
            workload[member["robot"]] += 1
    return workload


def run_row(*, sessions: sessionmaker[Session], run_id: str) -> Run:
    with sessions() as session:
        return require_run(session, run_id)


def list_run_rows(
    *, sessions: sessionmaker[Session], status: str | None, limit: int, offset: int, **where: str
) -> list[Run]:
    with sessions() as session:
        return repo.list_runs(session=session, status=status, limit=limit, offset=offset, **where)


@dataclass
class Trace:
    """A run's events with one page of its decisions (and their attempts)."""

    run: Run
    events: list[RunEvent]
    decisions: list[DecisionRecord]
    attempts: dict[int, list[Attempt]]
    total: int
    # A revision's decisions kept from its parent (docs/living-plans.md#revisions): task index ->
    # the parent decision's chain hash (`pinned_from`).
    pins: dict[int, str | None] = field(default_factory=dict)


def run_trace(
    *, sessions: sessionmaker[Session], run_id: str, offset: int = 0, limit: int | None = None
) -> Trace:
    with sessions() as session:
        run = require_run(session, run_id)
        page = decision_page(session, run_id, offset=offset, limit=limit)
        return Trace(
            run=run,
            events=repo.events(session=session, run_id=run_id),
            decisions=page.decisions,
            attempts=page.attempts,
            total=decision_repo.decision_count(session=session, run_id=run_id),
            pins=page.pins,
        )


@dataclass(frozen=True)
class DecisionPage:
    """One page of a run's decisions in task order, with their attempts by task."""

    decisions: list[DecisionRecord]
    attempts: dict[int, list[Attempt]]
    offset: int
    limit: int | None
    # A revision's decisions kept from its parent: task index -> the parent's chain hash.
    pins: dict[int, str | None]


def decision_page(
    session: Session,
    run_id: str,
    *,
    offset: int,
    limit: int | None,
    prompts: bool = True,
    from_task: bool = False,
) -> DecisionPage:
    """The one read of a page of decisions: the trace's (GET /runs/{id}/trace, the export)
    and the console's. `prompts=False` leaves the attempts' prompts and reply unloaded (a
    page shows them on demand); `from_task` reads the decisions of task indexes from
    `offset` on (the console's pages are task ranges) instead of skipping `offset` rows."""
    if from_task:
        assert limit is not None, "a task range needs its length"
        rows = decision_repo.decisions_window(
            session=session, run_id=run_id, offset=offset, limit=limit
        )
    else:
        rows = decision_repo.decisions_slice(
            session=session, run_id=run_id, offset=offset, limit=limit
        )
    read = decision_repo.attempts_of_tasks if prompts else decision_repo.attempt_summaries_of_tasks
    attempts = (
        read(session=session, run_id=run_id, first=rows[0].task_index, last=rows[-1].task_index)
        if rows
        else {}
    )
    return DecisionPage(
        decisions=[records.decision_record(d) for d in rows],
        attempts=attempts,
        offset=offset,
        limit=limit,
        pins=pins_of(rows),
    )


def pins_of(rows: Iterable[Any]) -> dict[int, str | None]:
    """Which of these decision rows a revision kept from its parent, with the parent
    decision's chain hash."""
    return {d.task_index: d.pinned_from for d in rows if d.pinned}


def _timed_reading(
    sessions: sessionmaker[Session],
    run_id: str,
    decisions: list[DecisionRecord],
    unplaced: set[int],
) -> tuple[list[dict[str, Any]], list[DecisionRecord]]:
    """A completed timed run's: what its plan breaks (docs/schedules.md#what-a-run-reports: a
    deadline nobody could meet, say), as POST /allocate says it, and its page's decisions with
    the unreported pins at the times the run placed them."""
    problem, schedule = _completed_plan(sessions, run_id)
    violations = violations_json(problem, check_schedule(problem, schedule))
    if unplaced & {d.task_index for d in decisions}:
        decisions = _placed_pins(schedule, decisions, unplaced)
    return violations, decisions


def _completed_plan(sessions: sessionmaker[Session], run_id: str) -> tuple[Problem, Schedule]:
    def load() -> tuple[Problem, Schedule]:
        planned = run_schedule(sessions=sessions, run_id=run_id)
        assert planned is not None  # a timed run
        return planned

    return _PLANS.get_or_load(run_id, load)


def _placed_pins(
    schedule: Schedule, decisions: list[DecisionRecord], unplaced: set[int]
) -> list[DecisionRecord]:
    """docs/living-plans.md#a-revision-in-time: a pin the site had not reported keeps the
    parent's row (its chain link), which has no times in the revision's plan; they are where
    the revision placed it, as its schedule says (run_schedule)."""
    slots = schedule.slots
    return [
        replace(
            d,
            start=slots[d.task_index].start,
            end=slots[d.task_index].end,
            zone=slots[d.task_index].zone,
            travel=slots[d.task_index].travel,
        )
        if d.task_index in unplaced
        else d
        for d in decisions
    ]


def run_schedule(
    *, sessions: sessionmaker[Session], run_id: str
) -> tuple[Problem, Schedule] | None:
    """A timed run's plan in time (docs/schedules.md#reading-a-runs-schedule), rebuilt from its
    stored decisions with build_schedule: (its problem, its schedule); None for an untimed run (it
    has no times). A task without a stored start (a revision's pin copied from a run before times
    were stored) is placed as the graph placed it (app.domain.scheduling.progress), from the
    stored robots. StateConflictError (409) while the run has not decided every task."""
    with sessions() as session:
        run = require_run(session, run_id)
        spec = _SPECS.get_or_load(run_id, lambda: RunSpec.from_json(run.request))
        rows = decision_repo.decisions(session=session, run_id=run_id)
    problem = spec.problem
    if not problem.instance.timed:
        return None
    n = problem.instance.n_tasks
    if len(rows) < n:
        raise StateConflictError(
            "run_id",
            f"run '{run_id}' has decided {len(rows)} of its {n} tasks ({run.status}); its "
            "schedule is whole once every task is decided: poll GET /runs/{id}",
        )
    robots = {d.task_index: d.robot for d in rows}
    starts = {d.task_index: d.start for d in rows if d.start is not None}
    # docs/allocation.md#teams: a team task sits in every member's lane.
    teams = decision_teams(problem, [records.decision_record(d) for d in rows if d.team])
    if len(starts) < n:
        with sessions() as session:
            # A guided run placed them in its stored plan's order (app.solvers.timed_guidance).
            order = records.run_problem(session, run_id, problem, spec.guidance)
        placed = TimedProgress.replay(order, robots, teams=teams).placed
        starts = {t: starts.get(t, placed[t].start) for t in range(n)}
    return problem, build_schedule(
        problem, [robots[t] for t in range(n)], [float(starts[t]) for t in range(n)], teams=teams
    )
