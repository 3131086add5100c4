"""GET /runs/{id}/schedule (docs/schedules.md#reading-a-runs-schedule): a timed run's plan in time,
as the schedule JSON block, CSV (one row per task) or iCalendar (one VEVENT per task), read
by app.schedule_views from the schedule rebuilt from the run's stored decisions and re-timed
by its execution reports (app.plans.current).

An untimed run has no times: 409, saying so (the run exists, it is the request that
cannot be served for it; 404 would read as "no such run"). So is a run that has not yet
decided every task: its schedule is not whole.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Response

from app.allocation.schedule_schemas import ScheduleOut
from app.domain.errors import StateConflictError
from app.exchange import write_mspdi
from app.http.deps import ClientDep
from app.http.responses import CLIENT, errors
from app.plans import current
from app.runs.deps import RunIdPath, RunsDep
from app.schedule_views import schedule_csv, schedule_ics, schedule_json

router = APIRouter(prefix="/runs", tags=["runs"])

CALENDAR_TYPE = "text/calendar; charset=utf-8"
CSV_TYPE = "text/csv; charset=utf-8"
MSPDI_TYPE = "application/vnd.ms-project+xml; charset=utf-8"
FORMATS: dict[int | str, dict[str, Any]] = {
    200: {
        "content": {
            CSV_TYPE: {"schema": {"type": "string"}},
            CALENDAR_TYPE: {"schema": {"type": "string"}},
            MSPDI_TYPE: {"schema": {"type": "string"}},
        },
        "description": "JSON by default; ?format=csv, ?format=ics or ?format=mspdi",
    }
}


@router.get(
    "/{run_id}/schedule",
    response_model=ScheduleOut,
    responses={**errors(*CLIENT, 404, 409, 410), **FORMATS},
)
def get_schedule(
    caller: ClientDep,
    run_id: RunIdPath,
    runs: RunsDep,
    format_: Annotated[
        Literal["json", "csv", "ics", "mspdi"],
        Query(
            alias="format",
            description="json (default): per robot its tasks in time order with travel and "
            "idle gaps; csv: one row per task; ics: iCalendar, one VEVENT per task; mspdi: "
            "MS Project XML (docs/exchange.md)",
        ),
    ] = "json",
) -> ScheduleOut | Response:
    """A timed run's schedule, once every task is decided (409 for an untimed run): its
    decisions, with the tasks the site reported at their reported times and what waits
    for them moved (docs/living-plans.md)."""
    # docs/living-plans.md#the-runs-current-schedule: the decisions re-timed by the site's execution
    # reports (living plans).
    planned = current.current_schedule(sessions=runs.sessions, run_id=run_id)
    if planned is None:
        raise StateConflictError(
            "run_id",
            f"run '{run_id}' has no times: its instance is untimed (no task has a "
            "'duration'); GET /runs/{id} has its assignments",
        )
    problem, schedule = planned
    if format_ == "mspdi":
        return Response(
            write_mspdi(problem, schedule, project_name=f"LTAA run {run_id}"),
            media_type=MSPDI_TYPE,
            headers={"Content-Disposition": f'attachment; filename="run-{run_id}.xml"'},
        )
    if format_ == "csv":
        return Response(
            schedule_csv(problem, schedule),
            media_type=CSV_TYPE,
            headers={"Content-Disposition": f'attachment; filename="run-{run_id}.csv"'},
        )
    if format_ == "ics":
        return Response(
            schedule_ics(
                problem,
                schedule,
                calendar_name=f"LTAA run {run_id}",
                uid_prefix=f"run-{run_id}",
            ),
            media_type=CALENDAR_TYPE,
            headers={"Content-Disposition": f'attachment; filename="run-{run_id}.ics"'},
        )
    return ScheduleOut.model_validate(schedule_json(problem, schedule))
