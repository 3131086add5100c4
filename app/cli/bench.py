"""`ltaa bench` and `ltaa bench-llm`: the benchmark scripts that write docs/.

The app never imports the `benchmarks` package (an import contract in pyproject.toml keeps
it so: the product must not depend on its measuring scripts). Each command runs its script
as `python -m benchmarks...` in a child process of this interpreter, with this process's
environment and working directory, and relays what the script prints."""

from __future__ import annotations

import subprocess
import sys
from typing import Annotated

import typer

from app.cli.root import cli


@cli.command()
def bench(
    section: Annotated[
        list[str] | None,
        typer.Argument(help="Only these benchmark modules (e.g. benchmarks.solvers)"),
    ] = None,
) -> None:
    """Measure every method and write docs/benchmarks.md and docs/img/*.png."""
    _run_benchmark("benchmarks.report", section or [])


@cli.command(
    "bench-llm",
    context_settings={"allow_extra_args": True, "ignore_unknown_options": True},
    add_help_option=False,
)
def bench_llm(ctx: typer.Context) -> None:
    """Run the 4 scenarios x 3 modes (scope all and contested, guided and unguided) with
    the configured LLM reasoner and write docs/llm-benchmark.md (options: `ltaa bench-llm
    --help`). Every call goes to the server the LTAA_* settings name, and costs what that
    server charges."""
    _run_benchmark("benchmarks.llm_live_cli", ctx.args)


def _run_benchmark(module: str, args: list[str]) -> None:
    """`python -m module args` with this interpreter; its output relayed line by line to
    stderr as it comes (the scripts report progress there), its exit status kept."""
    with subprocess.Popen(
        [sys.executable, "-m", module, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    ) as child:
        assert child.stdout is not None
        for line in child.stdout:
            typer.echo(line, nl=False, err=True)
    if child.returncode:
        raise typer.Exit(child.returncode)
