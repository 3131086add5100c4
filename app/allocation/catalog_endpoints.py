"""What the service offers: its solvers and its built-in scenarios."""

from __future__ import annotations

import logging

from fastapi import APIRouter

from app.allocation.schemas import ScenarioOut, SolverOut
from app.allocation.service import load_solver
from app.domain import catalog
from app.domain.errors import DomainError
from app.domain.serialize import instance_to_dict
from app.http.deps import ClientDep
from app.http.responses import CLIENT, errors
from app.solvers.registry import solver_names

router = APIRouter(tags=["catalog"])
log = logging.getLogger(__name__)


@router.get("/solvers", response_model=list[SolverOut], responses=errors(*CLIENT))
def list_solvers(caller: ClientDep) -> list[SolverOut]:
    """List the allocation methods usable in POST /allocate, with exactness and size limits."""
    out: list[SolverOut] = []
    for name in solver_names():
        try:
            info = load_solver(name).info
        except DomainError as exc:
            # An optional dependency is missing (e.g. torch for dqn): list what actually works.
            log.warning("solver %s left out of GET /solvers: %s", name, exc.message)
            continue
        out.append(
            SolverOut(
                name=info.name,
                description=info.description,
                exact=info.exact,
                kind="exact" if info.exact else "approximate",
                limits=info.limits,
            )
        )
    return out


@router.get(
    "/scenarios",
    response_model=list[ScenarioOut],
    response_model_exclude_none=True,
    responses=errors(*CLIENT),
)
def list_scenarios(caller: ClientDep) -> list[ScenarioOut]:
    """List the built-in scenarios: the 36 TEACh tasks and each scenario's robot success
    rates; the timed ones (`timed: true`) add durations, zones, precedence, releases and
    deadlines, the robots' start zones and shifts, travel times and the start; those with
    team tasks (`team: true`, docs/allocation.md#teams) give each such task its `team`."""
    listed = [(sc, False) for sc in catalog.scenarios().values()]
    listed += [(sc, True) for sc in catalog.timed_scenarios().values()]
    return [
        ScenarioOut.model_validate(
            {
                "name": sc.name,
                "description": sc.description,
                "timed": timed,
                "team": sc.instance.has_teams,
            }
            | instance_to_dict(sc.instance)
        )
        for sc, timed in listed
    ]
