"""A robot gone (docs/fleet.md#state-to-report): its connection OFFLINE or CONNECTIONBROKEN, or a
FATAL error. Every lineage head on the fleet that still has unfinished work for it is revised
with the robot unavailable, through the revisions' own service, once: the revision takes the
robot's tasks away, so the same news again finds nothing to revise.

A head whose every other robot is already gone is not revised (a revision needs a robot to
give the tasks to): the plan stays as it is, and its orders wait for its robots to come back
ONLINE (docs/fleet.md#no-robot-left)."""

from __future__ import annotations

import logging

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.domain.errors import DomainError
from app.domain.lifecycle import RunStatus
from app.fleet.dispatch import FINAL_REPORTS, FleetNames, on_the_fleet
from app.plans.revisions import RevisionRequest, create_revision
from app.runs.worker import RunWorker
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.models import Run

log = logging.getLogger("ltaa.fleet")

LEFT_AS_IS = (RunStatus.FAILED, RunStatus.CANCELLED, RunStatus.BLOCKED)
NO_ROBOT_LEFT = "no_robot_left"  # the revisions' refusal when every robot would be gone


def revise_without(
    *,
    sessions: sessionmaker[Session],
    worker: RunWorker,
    settings: Settings,
    names: FleetNames,
    robot: str,
    why: str,
) -> list[str]:
    """The revisions made, by id."""
    made = []
    for head in _heads_needing(sessions, names, robot):
        request = RevisionRequest(
            changes=[{"type": "robot_unavailable", "robot": robot}],
            pin="reported",
            reason=f"fleet: robot '{robot}' is unavailable ({why}), reported by the robot",
        )
        try:
            revision, _ = create_revision(
                sessions=sessions, worker=worker, parent_id=head, request=request, settings=settings
            )
        except DomainError as exc:
            if exc.code == NO_ROBOT_LEFT:
                log.warning(
                    "fleet: run %s keeps its plan: robot '%s' was the last it had (%s); its "
                    "orders wait for its robots to come back ONLINE",
                    head,
                    robot,
                    why,
                )
            else:
                log.warning("fleet: could not revise run %s without %s: %s", head, robot, exc)
            continue
        log.info("fleet: run %s revised as %s without robot %s (%s)", head, revision.id, robot, why)
        made.append(revision.id)
    return made


def _heads_needing(sessions: sessionmaker[Session], names: FleetNames, robot: str) -> list[str]:
    with sessions() as session:
        query = select(Run).where(Run.superseded_by.is_(None), Run.status.not_in(LEFT_AS_IS))
        heads = []
        for run in session.scalars(on_the_fleet(query, names)):
            fleet = {str(r["name"]) for r in run.request["instance_data"]["robots"]}
            if robot in fleet and _has_work(session, run, robot):
                heads.append(run.id)
        return heads


def _has_work(session: Session, run: Run, robot: str) -> bool:
    """Whether the run plans a task for the robot that is not reported done or failed, or it is
    still deciding (then its next decisions may name the robot)."""
    reports = {r.task_id: r.state for r in repo.execution_reports(session=session, run_id=run.id)}
    if run.status != RunStatus.COMPLETED:
        return True
    for d in decision_repo.decisions(session=session, run_id=run.id):
        members = [str(m["robot"]) for m in d.team] if d.team else [d.robot_name]
        if robot in members and reports.get(d.task_id) not in FINAL_REPORTS:
            return True
    return False
