"""`python -m benchmarks.llm_live_cli`, what `ltaa bench-llm` runs: the 4 scenarios x 3
modes with a live LLM reasoner, written to docs/llm-benchmark.md.

It lives here, not in app.cli, so that the app never imports the benchmarks (an import
contract in pyproject.toml): `ltaa bench-llm` starts this module in a child process."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from app.config import get_settings
from app.domain.errors import DomainError
from app.domain.modes import Mode
from app.solvers.ltaa import model_use_for
from benchmarks import llm_live

command = typer.Typer(add_completion=False)


class Format(StrEnum):
    JSON_SCHEMA = "json_schema"
    JSON_OBJECT = "json_object"
    MARKDOWN = "markdown"


@command.command()
def bench_llm(
    reasoner: Annotated[
        str, typer.Option(help="The LLM reasoner to measure: 'openai' or 'anthropic'")
    ] = "openai",
    model: Annotated[
        str | None, typer.Option(help="Model (default: LTAA_OPENAI_MODEL / the default model)")
    ] = None,
    scenario: Annotated[
        list[str] | None, typer.Option(help="Only these scenarios (default: all four)")
    ] = None,
    mode: Annotated[list[Mode] | None, typer.Option(help="Only these modes (default: all)")] = None,
    tasks: Annotated[
        int | None, typer.Option(min=1, help="Only the first N tasks of each scenario")
    ] = None,
    reply_format: Annotated[
        Format | None,
        typer.Option("--format", help="How the model is asked (default: LTAA_LLM_REPLY_FORMAT)"),
    ] = None,
    give_up: Annotated[
        int | None,
        typer.Option(
            min=0, help="Give up after N failed tasks in a row; 0 never (default: the setting)"
        ),
    ] = None,
    paper_only: Annotated[
        bool,
        typer.Option(
            "--paper-only",
            help="Only the paper's variant (scope all, unguided) instead of all four",
        ),
    ] = False,
    title: Annotated[
        str | None,
        typer.Option(help="The report section this run writes (default: model and settings)"),
    ] = None,
    out: Annotated[Path, typer.Option(help="Where the report goes")] = Path(
        "docs/llm-benchmark.md"
    ),
    label: Annotated[
        str | None,
        typer.Option(help="Who produced the figures, for the report (default: the endpoint)"),
    ] = None,
) -> None:
    """Run the 4 scenarios x 3 modes (scope all and contested, guided and unguided; or only
    the paper's variant) with the configured LLM reasoner and write its section of
    docs/llm-benchmark.md. Every call goes to the server the LTAA_* settings name, and costs
    what that server charges."""
    settings = get_settings()
    fmt = (reply_format or Format(settings.llm_reply_format)).value
    after = settings.llm_give_up_after if give_up is None else give_up
    try:
        make = llm_live.reasoner_factory(reasoner, settings=settings, model=model, reply_format=fmt)
    except DomainError as exc:  # a missing setting (DomainError is a ValueError too)
        typer.echo(f"{exc.field}: {exc.message}", err=True)
        raise typer.Exit(1) from None
    except ValueError as exc:
        typer.echo(str(exc), err=True)
        raise typer.Exit(2) from None
    endpoint, used_model = llm_live.server_of(reasoner, settings, model)
    given_up = f"give up after {after} failed tasks in a row" if after else "never given up"
    used = f"format `{fmt}`, {given_up}, output caps {settings.llm_max_tokens} by tier"
    typer.echo(f"bench-llm: {reasoner} model {used_model} at {endpoint}; {used}", err=True)

    def progress(cell: llm_live.LiveCell) -> None:
        typer.echo(
            f"  {cell.scenario}/{cell.mode} {cell.scope}"
            f"{' guided' if cell.guided else ''}: {cell.llm_tasks}/{cell.n_tasks} tasks "
            f"asked the model, {cell.model_decided} decided by it, {cell.tokens:,} tokens, "
            f"{cell.seconds:.1f} s",
            err=True,
        )

    cells = llm_live.run_cells(
        make,
        scenario_names=scenario,
        modes=mode or llm_live.MODES,
        n_tasks=tasks,
        progress=progress,
        variants=llm_live.VARIANTS[:1] if paper_only else llm_live.VARIANTS,
        model_use=model_use_for(reasoner, fmt, after),
    )
    section = llm_live.render(
        cells,
        title=title or f"{used_model}: {fmt}, {given_up}",
        reasoner=reasoner,
        endpoint=endpoint,
        model=used_model,
        label=label,
        settings=used,
    )
    typer.echo(f"wrote {llm_live.write(section, out)}", err=True)


if __name__ == "__main__":
    command()
