"""`ltaa allocate`: one allocation from the command line, as POST /allocate answers it."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path
from typing import Annotated, Any

import typer
from pydantic import ValidationError
from rich.console import Console
from rich.table import Table

from app.allocation.schemas import AllocateRequest, AllocateResponse
from app.allocation.service import allocate as run_allocation
from app.cli.root import cli, fail
from app.config import get_settings
from app.domain.errors import DomainError
from app.domain.modes import Mode
from app.http.errors import domain_error_body, validation_error_body
from app.http.rounding import rounded


@cli.command()
def allocate(
    solver: Annotated[str, typer.Option(help="Solver name (see GET /solvers)")] = "optimal",
    scenario: Annotated[str, typer.Option(help="Built-in scenario")] = "baseline",
    instance: Annotated[
        Path | None,
        typer.Option(
            help="JSON file with your own 'tasks' and 'robots', and for a timed instance "
            "'travel' and 'start' (replaces --scenario)",
            exists=True,
            dir_okay=False,
        ),
    ] = None,
    mode: Annotated[Mode, typer.Option(help="Operational mode")] = Mode.BALANCED,
    max_deviation: Annotated[
        float | None,
        typer.Option(help="Workload cap, in tasks either side of the target (default: the mode's)"),
    ] = None,
    seed: Annotated[int, typer.Option(help="Random seed")] = 0,
    option: Annotated[
        list[str] | None,
        typer.Option(
            "--option", "-o", help="Solver option KEY=VALUE (VALUE parsed as JSON); repeatable"
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the API's JSON response")] = False,
    show_tasks: Annotated[bool, typer.Option(help="Also list every task's assignment")] = False,
) -> None:
    """Allocate a task queue with one solver and print the assignments and metrics."""
    body: dict[str, Any] = {
        "solver": solver,
        "mode": mode.value,
        "seed": seed,
        "options": parse_options(option or []),
    }
    if max_deviation is not None:
        body["max_deviation"] = max_deviation
    if instance is None:
        body["scenario"] = scenario
    else:
        body.update(read_instance(instance, as_json))
    try:
        response = run_allocation(AllocateRequest.model_validate(body), get_settings())
    except ValidationError as exc:
        fail(validation_error_body(exc.errors(include_input=False), root=("body",)), as_json)
    except DomainError as exc:
        fail(domain_error_body(exc), as_json)
    if as_json:
        # Rounded as the API rounds, so the two print the same document.
        typer.echo(json.dumps(rounded(response.model_dump(mode="json")), indent=2))
    else:
        _print_report(response, show_tasks=show_tasks)


def parse_options(pairs: list[str]) -> dict[str, Any]:
    options: dict[str, Any] = {}
    for pair in pairs:
        key, sep, raw = pair.partition("=")
        if not sep or not key:
            raise typer.BadParameter(f"expected KEY=VALUE, got '{pair}'", param_hint="--option")
        try:
            options[key] = json.loads(raw)
        except json.JSONDecodeError:
            options[key] = raw  # bare words are strings: -o policy=greedy
    return options


def read_instance(path: Path, as_json: bool) -> dict[str, Any]:
    """The instance part of an /allocate body from a JSON file (other keys are ignored)."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        fail(
            {
                "detail": [
                    {"loc": ["instance"], "msg": f"not valid JSON: {exc}", "type": "json_invalid"}
                ]
            },
            as_json,
        )
    if not isinstance(doc, dict):
        fail(
            {
                "detail": [
                    {
                        "loc": ["instance"],
                        "msg": "expected a JSON object with 'tasks' and 'robots'",
                        "type": "model_type",
                    }
                ]
            },
            as_json,
        )
    return {key: doc[key] for key in ("tasks", "robots", "travel", "start") if key in doc}


def _print_report(r: AllocateResponse, *, show_tasks: bool) -> None:
    console = Console()  # made per call: tests swap sys.stdout
    m = r.metrics
    cap = "no cap" if r.max_deviation is None else f"cap ±{r.max_deviation:g} tasks"
    console.print(
        f"[bold]{r.solver}[/] · {r.mode.value} · {cap} · {len(r.assignments)} tasks · "
        f"{r.elapsed_ms:.1f} ms"
    )

    by_robot: dict[str, list[float]] = defaultdict(list)
    names: dict[str, list[str]] = defaultdict(list)
    for a in r.assignments:
        by_robot[a.robot].append(a.success)
        names[a.robot].append(a.task_name)
    robots = Table(title="Assignments by robot")
    for col in ("Robot", "Tasks", "Mean success", "Assigned"):
        robots.add_column(col, justify="right" if col in ("Tasks", "Mean success") else "left")
    for robot, load in m.workload.items():
        scores = by_robot.get(robot, [])
        mean = f"{sum(scores) / len(scores):.3f}" if scores else "-"
        shown = ", ".join(names[robot][:6]) + (", …" if len(names[robot]) > 6 else "")
        robots.add_row(robot, str(load), mean, shown)
    console.print(robots)

    if show_tasks:
        tasks = Table(title="Assignments in queue order")
        for col in ("#", "Task id", "Task", "Robot", "Success"):
            tasks.add_column(col)
        for i, a in enumerate(r.assignments):
            tasks.add_row(str(i), str(a.task_id), a.task_name, a.robot, f"{a.success:.3f}")
        console.print(tasks)

    metrics = Table(title="Metrics")
    metrics.add_column("Metric")
    metrics.add_column("Value", justify="right")
    sim = m.simulated_completion
    rows = [
        ("Expected success", f"{m.expected_success:.6f} ({m.expected_success:.1%})"),
        ("Balance score", f"{m.balance_score:.1f} / 100"),
        ("Max deviation", f"{m.max_deviation:g} tasks"),
        ("Imbalance severity", m.imbalance_severity),
        ("Jain index", f"{m.jain_index:.4f}"),
        (
            "Simulated completion",
            f"{sim.mean:.4f} (95% CI {sim.ci95[0]:.4f}–{sim.ci95[1]:.4f}, {sim.trials} trials)",
        ),
        *((f"Success on {f}", f"{v:.4f}") for f, v in m.feature_success.items()),
    ]
    if r.usage.llm_calls:
        rows.append(
            (
                "LLM calls / tokens in / out",
                f"{r.usage.llm_calls} / {r.usage.input_tokens} / {r.usage.output_tokens}",
            )
        )
    for name, value in rows:
        metrics.add_row(name, value)
    console.print(metrics)
