"""`python -m benchmarks.llm_live_cli`, what `ltaa bench-llm` runs: the 4 scenarios x 3
modes with a live LLM reasoner, written to docs/llm-benchmark.md.

It lives here, not in app.cli, so that the app never imports the benchmarks (an import
contract in pyproject.toml): `ltaa bench-llm` starts this module in a child process."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from app.config import get_settings
from app.domain.errors import DomainError
from app.domain.modes import Mode
from benchmarks import llm_live

command = typer.Typer(add_completion=False)


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
    out: Annotated[Path, typer.Option(help="Where the report goes")] = Path(
        "docs/llm-benchmark.md"
    ),
    label: Annotated[
        str | None,
        typer.Option(help="Who produced the figures, for the report (default: the endpoint)"),
    ] = None,
) -> None:
    """Run the 4 scenarios x 3 modes (scope all and contested, guided and unguided) with
    the configured LLM reasoner and write docs/llm-benchmark.md. Every call goes to the
    server the LTAA_* settings name, and costs what that server charges."""
    settings = get_settings()
    try:
        make = llm_live.reasoner_factory(reasoner, settings=settings, model=model)
    except DomainError as exc:  # a missing setting (DomainError is a ValueError too)
        typer.echo(f"{exc.field}: {exc.message}", err=True)
        raise typer.Exit(1) from None
    except ValueError as exc:
        typer.echo(str(exc), err=True)
        raise typer.Exit(2) from None
    endpoint, used_model = llm_live.server_of(reasoner, settings, model)
    typer.echo(f"bench-llm: {reasoner} model {used_model} at {endpoint}", err=True)

    def progress(cell: llm_live.LiveCell) -> None:
        typer.echo(
            f"  {cell.scenario}/{cell.mode} {cell.scope}"
            f"{' guided' if cell.guided else ''}: {cell.llm_tasks}/{cell.n_tasks} tasks "
            f"asked the model, {cell.tokens:,} tokens, {cell.seconds:.1f} s",
            err=True,
        )

    cells = llm_live.run_cells(
        make,
        scenario_names=scenario,
        modes=mode or llm_live.MODES,
        n_tasks=tasks,
        progress=progress,
    )
    text = llm_live.render(
        cells, reasoner=reasoner, endpoint=endpoint, model=used_model, label=label
    )
    typer.echo(f"wrote {llm_live.write(text, out)}", err=True)


if __name__ == "__main__":
    command()
