"""`ltaa schedule`: plan a timed instance with one method and print its schedule.

The per-robot timeline by default (rich), or the schedule as JSON (the `schedule` block
of POST /allocate's answer), CSV or iCalendar on stdout for a spreadsheet or a calendar, or
MS Project XML (MSPDI, docs/exchange.md) for MS Project, ProjectLibre or P6.
An instance file is read as an /allocate body's instance part and checked the same way;
a built-in name is a timed scenario (`baseline_timed`). Anything else, with `--format`
json, csv, ics or mspdi, is a run id on the server at `--url`: its current schedule as GET
/runs/{id}/schedule answers it (`ltaa schedule RUN --format mspdi` for MS Project).
"""

from __future__ import annotations

import json
from datetime import UTC, datetime
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import httpx
import typer
from pydantic import ValidationError
from rich.console import Console
from rich.markup import escape

from app.allocation.schemas import AllocateRequest
from app.allocation.service import build_problem, load_solver
from app.cli.allocate import parse_options, read_instance
from app.cli.reviews import ApiFailed, make_client
from app.cli.root import _URL, cli, fail
from app.config import get_settings
from app.domain import catalog
from app.domain.errors import DomainError
from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.schedule import Schedule
from app.exchange import write_mspdi
from app.http.errors import domain_error_body, validation_error_body
from app.http.rounding import rounded
from app.schedule_views import render_timeline, schedule_csv, schedule_ics, schedule_json


class Format(StrEnum):
    TEXT = "text"
    JSON = "json"
    CSV = "csv"
    ICS = "ics"
    MSPDI = "mspdi"


@cli.command()
def schedule(
    source: Annotated[
        str,
        typer.Argument(
            help="A JSON instance file (tasks, robots, travel, start) or a built-in timed "
            "scenario's name"
        ),
    ] = "baseline_timed",
    method: Annotated[str, typer.Option(help="Solver name (see GET /solvers)")] = "schedule",
    mode: Annotated[Mode, typer.Option(help="Operational mode")] = Mode.BALANCED,
    max_deviation: Annotated[
        float | None,
        typer.Option(help="Workload cap, in tasks either side of the target (default: the mode's)"),
    ] = None,
    objective: Annotated[
        ObjectiveKind, typer.Option(help="What the exact scheduler optimises")
    ] = ObjectiveKind.SUCCESS_THEN_MAKESPAN,
    min_expected_success: Annotated[
        float, typer.Option(help="With --objective makespan: the least expected success")
    ] = 0.0,
    time_limit: Annotated[
        float | None,
        typer.Option("--time-limit", help="Seconds for the `schedule` solver (default 10)"),
    ] = None,
    seed: Annotated[int, typer.Option(help="Random seed")] = 0,
    option: Annotated[
        list[str] | None,
        typer.Option("--option", "-o", help="Solver option KEY=VALUE (VALUE as JSON); repeatable"),
    ] = None,
    output: Annotated[Format, typer.Option("--format", help="What to print")] = Format.TEXT,
    url: _URL = "http://127.0.0.1:8000",
    key: Annotated[
        str | None,
        typer.Option("--key", envvar="LTAA_API_KEY", help="A client API key", show_default=False),
    ] = None,
) -> None:
    """Plan a timed instance and print when each robot does what (or print a server run's
    schedule: RUN with --format json, csv, ics or mspdi)."""
    as_json = output is Format.JSON
    if output is not Format.TEXT and _is_run(source):
        _print_run(source, output, url, key)
        return
    options = parse_options(option or [])
    if time_limit is not None:
        options["time_limit_s"] = time_limit
    try:
        problem = _problem(source, mode, max_deviation, objective, min_expected_success, as_json)
        if not problem.instance.timed:
            raise DomainError(
                "tasks",
                "the instance is untimed: give every task a 'duration' (minutes) to schedule it",
                code="not_timed",
            )
        solver = load_solver(method, get_settings())
        solution = solver.solve(problem, seed=seed, options=options)
    except ValidationError as exc:
        fail(validation_error_body(exc.errors(include_input=False), root=("body",)), as_json)
    except DomainError as exc:
        fail(domain_error_body(exc), as_json)
    planned: Schedule | None = solution.details.get("schedule")
    if planned is None:
        fail(_error("method", str(solution.details.get("schedule_error")), "no_schedule"), as_json)
    _warn_violations(problem, planned)
    if output is Format.JSON:
        typer.echo(json.dumps(rounded(schedule_json(problem, planned)), indent=2))
    elif output is Format.CSV:
        typer.echo(schedule_csv(problem, planned), nl=False)
    elif output is Format.MSPDI:
        # Minute 0 is now when the instance names no start, as for iCalendar.
        xml = write_mspdi(
            problem,
            planned,
            project_name=f"{Path(source).stem}: {method}",
            start=datetime.now(UTC).replace(second=0, microsecond=0),
        )
        typer.echo(xml.decode("utf-8"), nl=False)
    elif output is Format.ICS:
        name = Path(source).stem
        typer.echo(
            schedule_ics(
                problem,
                planned,
                calendar_name=f"{name}: {method}",
                uid_prefix=f"ltaa-{name}-{method}",
                start=datetime.now(UTC).replace(microsecond=0),
            ),
            nl=False,
        )
    else:
        console = Console()  # made per call: tests swap sys.stdout
        _print_header(console, method, solution.details, planned)
        render_timeline(problem, planned, console)


def _problem(
    source: str,
    mode: Mode,
    max_deviation: float | None,
    objective: ObjectiveKind,
    min_expected_success: float,
    as_json: bool,
) -> Problem:
    path = Path(source)
    if path.is_file():
        body: dict[str, Any] = {
            "solver": "schedule",  # checked on its own by load_solver
            "mode": mode.value,
            "objective": objective.value,
            "min_expected_success": min_expected_success,
            **read_instance(path, as_json),
        }
        if max_deviation is not None:
            body["max_deviation"] = max_deviation
        return build_problem(AllocateRequest.model_validate(body))
    if source not in catalog.timed_scenarios():
        known = ", ".join(catalog.timed_scenarios())
        raise DomainError(
            "source",
            f"'{source}' is neither a file nor a timed scenario; name an instance file or "
            f"one of: {known}",
            code="unknown_scenario",
        )
    return Problem.build(
        catalog.timed_scenario(source).instance,
        mode,
        max_deviation,
        objective=Objective(objective, min_expected_success),
    )


def _is_run(source: str) -> bool:
    return not Path(source).is_file() and source not in catalog.timed_scenarios()


def _print_run(run_id: str, output: Format, url: str, key: str | None) -> None:
    """A server run's current schedule in `output`'s format, as the server writes it."""
    try:
        with make_client(url, key) as client:
            answer = client.get(f"/runs/{run_id}/schedule", params={"format": output.value})
        if answer.status_code != 200:
            raise ApiFailed(answer)
    except (ApiFailed, httpx.HTTPError) as exc:
        known = ", ".join(catalog.timed_scenarios())
        message = (
            f"'{run_id}' is neither a file nor a timed scenario ({known}), and the server at "
            f"{url} has no schedule for a run of that id ({exc})"
        )
        fail(_error("source", message, "unknown_source"), output is Format.JSON)
    typer.echo(answer.text, nl=False)


def _error(field: str, message: str, type_: str) -> dict[str, Any]:
    return {"detail": [{"loc": ["body", field], "msg": message, "type": type_}]}


def _warn_violations(problem: Problem, planned: Schedule) -> None:
    """The rules this schedule breaks (a method's assignment may miss a deadline), on
    stderr so that stdout stays the schedule alone."""
    err = Console(stderr=True)
    for violation in check_schedule(problem, planned):
        err.print(
            f"[bold yellow]breaks[/] {violation.rule.value}: {escape(violation.message)}",
            highlight=False,
        )


def _print_header(
    console: Console, method: str, details: dict[str, Any], planned: Schedule
) -> None:
    line = f"[bold]{method}[/] · makespan {planned.makespan:g} min"
    if "status" in details:
        line += f" · {details['status']} (bound {details['bound']:g}, gap {details['gap']:.1%})"
    else:
        line += " · timed by the list scheduler"
    console.print(line, highlight=False)
