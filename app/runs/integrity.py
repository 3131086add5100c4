"""The check made before a run resumes: is the stored record consistent with the checkpoint?
If not, the run fails here, saying why, instead of resuming."""

from __future__ import annotations

import bisect
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

from langgraph.checkpoint.base import CheckpointTuple
from sqlalchemy.orm import Session

from app.domain.metrics import balance_score
from app.domain.phases import detect_phase
from app.domain.problem import Problem
from app.domain.scheduling.progress import TimedProgress, decision_order
from app.graph.recorder import DecisionRecord
from app.graph.timing import decision_teams
from app.runs import lifecycle, records
from app.runs.lifecycle import EventKind, RunStatus
from app.runs.spec import RunSpec
from app.store import decision_repository as decision_repo
from app.store.models import Run


def timed_order(problem: Problem, stored: Sequence[DecisionRecord]) -> tuple[int, ...]:
    """A timed run's free tasks in the order the graph decides them, as far as the stored
    decisions fix it: those decisions replayed (a team in every member's lane), then the
    task that comes next, then the rest (in queue order: they wait on decisions not made)."""
    robots = {d.task_index: d.robot for d in stored}
    teams = decision_teams(problem, stored)
    progress = TimedProgress.replay(problem, robots, teams=teams)
    made = decision_order(problem, robots, teams)
    nxt = progress.current()
    head = [*made, nxt] if nxt < problem.instance.n_tasks else made
    seen = set(head)
    return (*head, *(t for t in problem.free_tasks if t not in seen))


@dataclass(frozen=True)
class IntegrityReport:
    ok: bool
    decisions_stored: int
    contiguous: bool
    checkpoint_task_index: int | None
    resume_at_task: int
    loads_from_decisions: list[int]
    loads_in_checkpoint: list[int] | None
    loads_consistent: bool
    phase: str
    balance_score: float
    problems: list[str]
    pinned: int = 0  # a revision's pins among decisions_stored

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def check_integrity(
    *,
    decisions: list[DecisionRecord],
    n_tasks: int,
    n_robots: int,
    checkpoint: dict[str, Any] | None,
    pinned: Mapping[int, int] | None = None,
    free_tasks: Sequence[int] | None = None,
    initial_loads: Sequence[int] | None = None,
    balance_robots: Sequence[int] | None = None,
    target: float | None = None,
    robot_names: Sequence[str] = (),
) -> IntegrityReport:
    """Queue position, loads recomputed from stored decisions, phase re-derived.

    A checkpoint may lag the decisions table by the one task whose `store_and_route`
    node wrote its decision but did not finish: that node re-runs and upserts the same
    row, so a lag of exactly one is consistent. Anything else is reported as a problem.

    A revision (docs/living-plans.md#pins) also has `pinned` rows (task index -> robot) written when
    it was created: each pin must be stored on its robot, the graph's decisions must be a prefix
    of the `free_tasks`, and loads count from `initial_loads` (the pins on available robots).
    `free_tasks` is the order the graph decides in: queue order, or on a timed instance the
    order in time (app.domain.scheduling.progress.decision_order and the next task).
    A team decision (docs/allocation.md#teams) adds one to each member: `robot_names` reads them.
    """
    problems: list[str] = []
    index = {name: i for i, name in enumerate(robot_names)}
    pins = dict(pinned or {})
    free = list(free_tasks) if free_tasks is not None else list(range(n_tasks))
    stored_pins = {d.task_index: d.robot for d in decisions if d.task_index in pins}
    place = {t: i for i, t in enumerate(free)}
    graph_made = sorted(
        (d for d in decisions if d.task_index not in pins),
        key=lambda d: (place.get(d.task_index, len(free)), d.task_index),
    )
    problems += _pin_problems(pins, stored_pins)
    indices = [d.task_index for d in graph_made]
    contiguous = indices == free[: len(indices)]
    if not contiguous:
        problems.append(
            f"decision task indices are not the first {len(indices)} free tasks: {indices[:10]}"
        )
    start = list(initial_loads) if initial_loads is not None else [0] * n_robots
    loads = _replayed_loads(graph_made, start, problems, index)
    cp_index = checkpoint.get("task_index") if checkpoint else None
    cp_loads = list(checkpoint["loads"]) if checkpoint and "loads" in checkpoint else None
    loads_consistent = True
    if cp_index is not None:
        loads_consistent = _checkpoint_agrees(
            checkpoint or {}, cp_index, cp_loads, graph_made, free, place, start, problems, index
        )
    resume_at = free[len(graph_made)] if len(graph_made) < len(free) else n_tasks
    w = target if target is not None else n_tasks / n_robots
    counted_loads = [loads[r] for r in balance_robots] if balance_robots is not None else loads
    return IntegrityReport(
        ok=not problems,
        decisions_stored=len(decisions),
        contiguous=contiguous,
        checkpoint_task_index=cp_index,
        resume_at_task=resume_at,
        loads_from_decisions=loads,
        loads_in_checkpoint=cp_loads,
        loads_consistent=loads_consistent,
        phase=detect_phase(len(pins) + len(graph_made), n_tasks).value,
        balance_score=balance_score(counted_loads, w),
        problems=problems,
        pinned=len(pins),
    )


def _pin_problems(pins: Mapping[int, int], stored_pins: Mapping[int, int]) -> list[str]:
    if stored_pins == pins:
        return []
    missing = sorted(set(pins) - set(stored_pins))
    wrong = sorted(t for t, r in stored_pins.items() if pins[t] != r)
    return [
        f"pinned tasks missing {missing[:10]} or on another robot {wrong[:10]} "
        "in the stored decisions"
    ]


def _members(d: DecisionRecord, index: Mapping[str, int]) -> list[int]:
    """The robots a decision adds one to: its team's members, or its robot."""
    return [index[m["robot"]] for m in d.team] if d.team else [d.robot]


def _replayed_loads(
    graph_made: Sequence[DecisionRecord],
    start: Sequence[int],
    problems: list[str],
    index: Mapping[str, int],
) -> list[int]:
    """The loads the graph's decisions give, each checked against its stored loads_after."""
    loads = list(start)
    for d in graph_made:
        for r in _members(d, index):
            loads[r] += 1
        if d.loads_after != loads:
            problems.append(
                f"task {d.task_index}: stored loads_after {d.loads_after} but the "
                f"decisions so far give {loads}"
            )
            break
    return loads


def _checkpoint_agrees(
    checkpoint: Mapping[str, Any],
    cp_index: int,
    cp_loads: list[int] | None,
    graph_made: Sequence[DecisionRecord],
    free: Sequence[int],
    place: Mapping[int, int],
    start: Sequence[int],
    problems: list[str],
    index: Mapping[str, int],
) -> bool:
    """Whether the checkpoint's loads agree with the stored decisions (a lag of one task is
    consistent); problems gets what disagrees."""
    # Free tasks before the checkpoint's task: what the graph had stored by then.
    position = place.get(cp_index, bisect.bisect_left(free, cp_index))
    lag = len(graph_made) - position
    if lag not in (0, 1):
        problems.append(
            f"checkpoint is at task {cp_index} but {len(graph_made)} decisions are stored"
        )
    if cp_loads is None:
        return True
    expected = list(start)
    for d in graph_made[: min(position, len(graph_made))]:
        for r in _members(d, index):
            expected[r] += 1
    # The checkpoint may already count the current task (after update_workload),
    # whose decision is stored only by the next node: its robot (or team) is then the
    # checkpoint's own `robot` (and its `decision` scratch's team).
    current = graph_made[position] if position < len(graph_made) else None
    if current is not None:
        members: list[Any] = _members(current, index)
    else:
        members = (checkpoint.get("decision") or {}).get("team") or [checkpoint.get("robot")]
    counted = expected.copy()
    for r in members:
        if isinstance(r, int) and 0 <= r < len(counted):
            counted[r] += 1
    consistent = cp_loads in (expected, counted)
    if not consistent:
        problems.append(
            f"checkpoint loads {cp_loads} disagree with the stored decisions ({expected})"
        )
    return consistent


def checked_for_resume(
    session: Session,
    run: Run,
    spec: RunSpec,
    checkpoint: CheckpointTuple | None,
    detail: dict[str, Any],
) -> IntegrityReport | None:
    """The check made before a run resumes, on the stored decisions and the checkpoint.
    If it fails, the run is failed here with an `integrity_failed` event saying why (None):
    resuming would build on a record the checkpoint contradicts."""
    run_id = run.id
    instance = spec.problem.instance
    stored = [
        records.decision_record(d) for d in decision_repo.decisions(session=session, run_id=run_id)
    ]
    values = checkpoint.checkpoint["channel_values"] if checkpoint else None
    # A guided timed run decides in its stored plan's order (app.solvers.timed_guidance).
    problem = records.run_problem(session, run_id, spec.problem, spec.guidance)
    order = problem.free_tasks
    if instance.timed:
        order = timed_order(problem, stored)
    report = check_integrity(
        decisions=stored,
        n_tasks=instance.n_tasks,
        n_robots=instance.n_robots,
        checkpoint=values,
        pinned=problem.pinned,
        free_tasks=order,
        initial_loads=problem.initial_loads,
        balance_robots=problem.available,
        target=problem.target,
        robot_names=[r.name for r in instance.robots],
    )
    if not report.ok:
        # Resuming would build on a record that the checkpoint contradicts, and its
        # final allocation could not be trusted: stop here, say why.
        lifecycle.record_event(
            session,
            run_id=run_id,
            kind=EventKind.INTEGRITY_FAILED,
            detail={"integrity": report.as_dict(), **detail},
        )
        lifecycle.move(
            session,
            run,
            RunStatus.FAILED,
            error="not resumed: the integrity check failed ("
            + "; ".join(report.problems)
            + "). The stored decisions and the "
            "checkpoint disagree; inspect GET /runs/{id}/trace and /trace/verify, "
            "then start a new run.",
        )
        return None
    return report
