"""A revision against its parent (docs/living-plans.md#the-lineage-and-the-diff): what moved, what
was added or removed, what the fleet lost or gained, and expected success and balance before and
after."""

from __future__ import annotations

import statistics
from dataclasses import dataclass
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from app.domain.errors import RunNotFoundError, StateConflictError
from app.domain.metrics import balance_score
from app.graph.recorder import DecisionRecord
from app.plans.current import current_schedule
from app.plans.revisions import RevisionConflictError
from app.plans.schedule_moves import Timed, time_moves
from app.runs import records
from app.runs.spec import RunSpec
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.models import Run


@dataclass(frozen=True)
class Diff:
    run_id: str
    parent: str
    robot_changes: list[dict[str, Any]]
    added_tasks: list[int | str]
    removed_tasks: list[int | str]
    fleet_changes: list[dict[str, Any]]
    before: dict[str, Any]
    after: dict[str, Any]
    # docs/living-plans.md#the-diff-in-time: start/end moves and the makespans
    # (app.plans.schedule_moves); None for an untimed revision, and until both plans have decided
    # every task.
    schedule: dict[str, Any] | None = None


def side(run: Run, spec: RunSpec, decisions: list[DecisionRecord]) -> dict[str, Any]:
    """Expected success over the decided tasks (the recorded success of each, pins
    included) and the balance of their loads over the robots in the balance."""
    problem = spec.problem
    loads = [0] * problem.instance.n_robots
    index = {r.name: i for i, r in enumerate(problem.instance.robots)}
    for d in decisions:
        # A team decision counts once for each member (docs/allocation.md#teams).
        for member in [index[m["robot"]] for m in d.team] if d.team else [d.robot]:
            loads[member] += 1
    es = statistics.fmean(d.expected_success for d in decisions) if decisions else None
    return {
        "expected_success": es,
        "balance_score": balance_score(problem.cap.balanced(loads), problem.target)
        if decisions
        else None,
        "decided": len(decisions),
        "total": run.n_tasks,
    }


def _held(d: DecisionRecord) -> list[Any]:
    """What a decision gives a task: its robot, or its team's members unit by unit."""
    return [(m["robot"], m["feature"]) for m in d.team] if d.team else [d.robot_name]


def _team_change(was: DecisionRecord, now: DecisionRecord) -> dict[str, Any]:
    """docs/living-plans.md#teams-in-a-revision: a team task's members before and after, and
    who left and joined it (a change of any member, not only the first)."""
    if not (was.team or now.team):
        return {}
    before = [m["robot"] for m in was.team or []]
    after = [m["robot"] for m in now.team or []]
    return {
        "from_team": was.team,
        "to_team": now.team,
        "members_left": [r for r in before if r not in after],
        "members_joined": [r for r in after if r not in before],
    }


def _load(session: Session, run_id: str) -> tuple[Run, RunSpec, list[DecisionRecord]]:
    run = repo.get_run(session=session, run_id=run_id)
    if run is None:
        raise RunNotFoundError(run_id)
    decisions = [
        records.decision_record(d) for d in decision_repo.decisions(session=session, run_id=run_id)
    ]
    return run, RunSpec.from_json(run.request), decisions


def diff(*, sessions: sessionmaker[Session], run_id: str) -> Diff:
    with sessions() as session:
        run, spec, after = _load(session, run_id)
        if run.revision_of is None:
            raise RevisionConflictError(
                f"run '{run_id}' is not a revision; GET /runs/{{id}}/diff compares a "
                "revision with the run it revised"
            )
        parent, parent_spec, before = _load(session, run.revision_of)
        first = repo.events_page(session=session, run_id=run_id, after_seq=0, limit=1)
        detail = first[0].detail if first else {}
    old = {str(t["id"]) for t in parent_spec.instance_data["tasks"]}
    new = {str(t["id"]) for t in spec.instance_data["tasks"]}
    decided_before = {str(d.task_id): d for d in before}
    changes = []
    for d in after:
        was = decided_before.get(str(d.task_id))
        if was is not None and _held(was) != _held(d):
            changes.append(
                {
                    "task_id": d.task_id,
                    "task_name": d.task_name,
                    "from_robot": was.robot_name,
                    "to_robot": d.robot_name,
                    "success_before": was.expected_success,
                    "success_after": d.expected_success,
                    **_team_change(was, d),
                }
            )
    order = [t["id"] for t in spec.instance_data["tasks"]]
    parent_order = [t["id"] for t in parent_spec.instance_data["tasks"]]
    original = {str(t): t for t in order}
    for c in changes:
        c["task_id"] = original.get(str(c["task_id"]), c["task_id"])
    return Diff(
        run_id=run_id,
        parent=parent.id,
        robot_changes=changes,
        added_tasks=[t for t in order if str(t) not in old],
        removed_tasks=[t for t in parent_order if str(t) not in new],
        fleet_changes=list(detail.get("fleet_changes", [])),
        before=side(parent, parent_spec, before),
        after=side(run, spec, after),
        # An untimed revision reads no schedule (nor its decisions a second time).
        schedule=_schedule_moves(sessions, parent.id, run_id)
        if spec.problem.instance.timed
        else None,
    )


def _schedule_moves(
    sessions: sessionmaker[Session], parent_id: str, run_id: str
) -> dict[str, Any] | None:
    """The parent's current schedule (its decisions re-timed by its reports) against the
    revision's; None when either has no whole schedule (untimed, or still deciding)."""
    try:
        was = current_schedule(sessions=sessions, run_id=parent_id)
        now = current_schedule(sessions=sessions, run_id=run_id)
    except StateConflictError:
        return None
    if was is None or now is None:
        return None
    return time_moves(Timed(*was), Timed(*now))
