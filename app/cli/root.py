"""The `ltaa` command group, and what its commands share."""

from __future__ import annotations

import json
from typing import Annotated, Any, NoReturn

import typer
from rich.console import Console
from rich.markup import escape

from app.config import Settings

cli = typer.Typer(
    name="ltaa",
    help="LTAA allocation service: serve the HTTP API or allocate from the command line.",
    no_args_is_help=True,
    add_completion=False,
)


@cli.callback()
def _root() -> None:
    # A callback keeps `ltaa <command>` a command group even while it has few commands.
    pass


_URL = Annotated[
    str,
    typer.Option("--url", envvar="LTAA_URL", help="The server [default: http://127.0.0.1:8000]"),
]
_KEY = Annotated[
    str | None,
    typer.Option("--key", envvar="LTAA_API_KEY", help="A supervisor API key", show_default=False),
]


def apply_migrations(settings: Settings) -> None:
    """Bring the database to the latest schema before serving (never at import)."""
    from app.store.migrate import upgrade_head  # alembic loads only for this command

    settings.data_dir.mkdir(parents=True, exist_ok=True)  # SQLite will not create parent dirs
    upgrade_head(settings.db_url)


def fail(body: dict[str, Any], as_json: bool) -> NoReturn:
    """Report an invalid request the way the API would (same JSON under --json) and exit 1."""
    if as_json:
        typer.echo(json.dumps(body, indent=2))
    else:
        err = Console(stderr=True)
        for item in body["detail"]:
            where = ".".join(str(p) for p in item["loc"][1:]) or "request"
            # The message quotes names from the request: print them as text, not markup.
            err.print(
                f"[bold red]error[/] [cyan]{escape(where)}[/]: {escape(item['msg'])}",
                highlight=False,
            )
    raise typer.Exit(code=1)
