"""The `ltaa` command line, one module per command group: serve, allocate, runs, store
(backup, restore, archive, keygen), revise, reviews, estimates, bench, schedule, import
(exchange), fleet (the simulator). Importing a module registers its commands on the one `cli` group
(app.cli.root)."""

from __future__ import annotations

from app.cli import (
    allocate,
    bench,
    estimates,
    exchange,
    fleet,
    reviews,
    revise,
    runs,
    schedule,
    serve,
    store,
)
from app.cli.root import apply_migrations, cli

__all__ = ["apply_migrations", "cli", "main"]
# Imported for their commands.
_COMMAND_MODULES = (
    allocate,
    bench,
    estimates,
    exchange,
    fleet,
    reviews,
    revise,
    runs,
    schedule,
    serve,
    store,
)


def main() -> None:
    cli()
