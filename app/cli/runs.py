"""`ltaa run`: a durable LTAA run in the local data directory, with a progress bar.

The same run service the HTTP API uses (migrations, worker, checkpointer), so a run
started here shows up in GET /runs of a server on the same data directory.
"""

from __future__ import annotations

import time
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from app.cli.root import cli, fail
from app.config import Settings, get_settings
from app.domain.catalog import scenario as builtin_scenario
from app.domain.errors import DomainError
from app.domain.lifecycle import ACTIVE, RunStatus
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.http.errors import domain_error_body
from app.reasoners.scope import LLMScope
from app.runs import service, views
from app.runs.factory import make_worker
from app.runs.spec import RunSpec
from app.store.db import make_engine, make_session_factory
from app.store.migrate import upgrade_head


def run_locally(
    settings: Settings,
    *,
    scenario: str,
    mode: Mode,
    reasoner: str,
    max_deviation: float | None,
    guidance: str | None,
    console: Console,
    llm_scope: str = "all",
) -> views.RunView:
    problem = Problem.build(builtin_scenario(scenario).instance, mode, max_deviation)
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    upgrade_head(settings.db_url)
    engine = make_engine(settings.db_url)
    sessions = make_session_factory(engine)
    worker = make_worker(settings=settings, sessions=sessions)
    try:
        spec = RunSpec.for_instance(
            problem.instance,
            mode=mode.value,
            max_deviation=problem.cap.max_deviation,
            reasoner=reasoner,
            guidance=guidance,
            token_budget=settings.run_token_budget,
            llm_scope=llm_scope,
            reply_format=settings.llm_reply_format,
            llm_give_up_after=settings.llm_give_up_after,
        )
        run = service.create_run(sessions=sessions, worker=worker, settings=settings, spec=spec)
        columns = (
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[phase]}"),
            TimeElapsedColumn(),
        )
        with Progress(*columns, console=console) as bar:
            task = bar.add_task(f"run {run.id[:8]}", total=problem.instance.n_tasks, phase="early")
            while True:
                view = views.run_view(sessions=sessions, run_id=run.id)
                bar.update(task, completed=view.progress["allocated"], phase=view.progress["phase"])
                if view.run.status not in ACTIVE:
                    break
                time.sleep(0.05)
        return view
    finally:
        worker.close()
        engine.dispose()


def print_summary(view: views.RunView, console: Console) -> None:
    table = Table(title=f"Run {view.run.id}: {view.run.status}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_row("reasoner / mode", f"{view.run.reasoner} / {view.run.mode}")
    table.add_row("decisions", f"{len(view.decisions)} of {view.run.n_tasks}")
    table.add_row("workload", ", ".join(f"{k} {v}" for k, v in view.workload.items()))
    if view.metrics is not None:
        m = view.metrics
        table.add_row("expected success", f"{m.expected_success:.4f}")
        table.add_row("balance score", f"{m.balance_score:.1f} ({m.imbalance_severity})")
        table.add_row(
            "simulated completion",
            f"{m.simulated_completion.mean:.4f} "
            f"[{m.simulated_completion.ci95[0]:.4f}, "
            f"{m.simulated_completion.ci95[1]:.4f}]",
        )
    fallbacks = sum(d.fallback for d in view.decisions)
    retries = sum(d.attempts - 1 for d in view.decisions)
    table.add_row("retries / fallbacks", f"{retries} / {fallbacks}")
    if view.decisions:
        mean_q = sum(d.quality for d in view.decisions) / len(view.decisions)
        table.add_row("mean validation quality Q", f"{mean_q:.3f}")
    table.add_row(
        "LLM calls / tokens in / out",
        f"{view.usage.llm_calls} / {view.usage.input_tokens} / {view.usage.output_tokens}",
    )
    if view.run.error:
        table.add_row("error", view.run.error)
    console.print(table)


@cli.command()
def run(
    scenario: Annotated[str, typer.Option(help="Built-in scenario")] = "baseline",
    mode: Annotated[Mode, typer.Option(help="Operational mode")] = Mode.BALANCED,
    reasoner: Annotated[
        str, typer.Option(help="'rules' (offline), 'anthropic' or 'openai'")
    ] = "rules",
    max_deviation: Annotated[
        float | None,
        typer.Option(help="Workload cap, in tasks either side of the target (default: the mode's)"),
    ] = None,
    guidance: Annotated[
        str | None,
        typer.Option(help="'optimizer' to give the reasoner the optimal completion's choice"),
    ] = None,
    llm_scope: Annotated[
        LLMScope,
        typer.Option(help="'contested': ask an LLM reasoner only for contested decisions"),
    ] = LLMScope.ALL,
) -> None:
    """Run the LTAA graph durably in the local data directory, with a progress bar."""
    from app.store.lock import StoreInUseError

    console = Console()
    try:
        view = run_locally(
            get_settings(),
            scenario=scenario,
            mode=mode,
            reasoner=reasoner,
            max_deviation=max_deviation,
            guidance=guidance,
            console=console,
            llm_scope=llm_scope.value,
        )
    except DomainError as exc:
        fail(domain_error_body(exc), as_json=False)
    except StoreInUseError as exc:  # a server (or another `ltaa run`) has the data directory
        Console(stderr=True).print(f"[bold red]error[/]: {exc}", highlight=False)
        raise typer.Exit(code=1) from None
    print_summary(view, console)
    if view.run.status != RunStatus.COMPLETED:
        raise typer.Exit(1)
