"""`ltaa estimates` and `ltaa rebuild-estimates` (docs/estimates.md#sites).

`ltaa estimates [SITE]` reads a running server's estimates over its API, like `ltaa
reviews` (the server and key from `--url` / `LTAA_URL` and `--key` / `LTAA_API_KEY`, a client
key will do); without a site it lists the sites. `ltaa rebuild-estimates` recomputes the
outcome table from the record, directly on the store: on SQLite under the store's lock
(stop the server first), on PostgreSQL with the table locked while it is rewritten.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import httpx
import typer
from rich.console import Console
from rich.table import Table

from app.cli.reviews import ApiFailed, make_client
from app.cli.root import _URL, cli
from app.config import get_settings

_CLIENT_KEY = Annotated[
    str | None,
    typer.Option("--key", envvar="LTAA_API_KEY", help="A client API key", show_default=False),
]


def _pct(x: float) -> str:
    return f"{x * 100:.1f}%"


# Why a started/done pair taught no duration (the API's `left_out` reasons).
_LEFT_OUT = {
    "together_without_at": "sent together without at",
    "zero_length": "no time between",
}


def _left_out(reasons: dict[str, int]) -> str:
    return "; ".join(f"{n} {_LEFT_OUT.get(why, why)}" for why, n in reasons.items()) or "-"


def _get(client: httpx.Client, path: str, **params: str) -> Any:
    answer = client.get(path, params=params)
    if answer.status_code != 200:
        raise ApiFailed(answer)
    return answer.json()


def print_sites(found: list[dict[str, Any]], console: Console) -> None:
    if not found:
        console.print("No run names a site yet.")
        return
    table = Table(title="Sites")
    for column in ("site", "runs", "reports", "last run"):
        table.add_column(column)
    for s in found:
        table.add_row(s["site"], str(s["runs"]), str(s["reports"]), str(s["last_run_at"]))
    console.print(table)


def print_estimates(body: dict[str, Any], console: Console) -> None:
    when = f"as of {body['as_of']}" if body["as_of"] else f"at {body['computed_at']}"
    table = Table(
        title=f"Site {body['site']}: {body['reports']} report(s), {when}; prior weight "
        f"{body['prior_strength']:g} reports, 90% intervals ([bold]*[/] = far from configured)"
    )
    for column in ("robot", "feature", "configured", "done", "failed", "learned", "90% interval"):
        table.add_column(column)
    for robot in body["robots"]:
        for f in robot["features"]:
            low, high = f["interval"]
            table.add_row(
                robot["robot"],
                f["feature"],
                _pct(f["prior"]) if f["configured"] else "[dim]none (50%)[/]",
                str(f["successes"]),
                str(f["failures"]),
                ("[bold]*[/] " if f["marked"] else "") + _pct(f["posterior_mean"]),
                f"{_pct(low)} - {_pct(high)}",
            )
    console.print(table)
    rows = [(r["robot"], d) for r in body["robots"] for d in r["durations"]]
    if rows:
        durations = Table(title="Durations (minutes): planned against observed (log-normal)")
        columns = ("robot", "task type", "planned", "observed", "median seen", "estimate")
        for column in (*columns, "left out"):
            durations.add_column(column)
        for robot, d in rows:
            durations.add_row(
                robot,
                d["task_type"],
                "-" if d["planned_minutes"] is None else f"{d['planned_minutes']:.1f}",
                str(d["observed"]),
                "-"
                if d["observed_median_minutes"] is None
                else f"{d['observed_median_minutes']:.1f}",
                "-" if d["estimate_minutes"] is None else f"{d['estimate_minutes']:.1f}",
                _left_out(d.get("left_out", {})),
            )
        console.print(durations)


@cli.command()
def estimates(
    site: Annotated[
        str | None, typer.Argument(help="The site (default: list the sites)", show_default=False)
    ] = None,
    as_of: Annotated[
        str | None,
        typer.Option("--as-of", help="RFC 3339 with an offset: the estimates at that time"),
    ] = None,
    url: _URL = "http://127.0.0.1:8000",
    key: _CLIENT_KEY = None,
) -> None:
    """A site's learned success rates and durations (GET /sites/{site}/estimates)."""
    try:
        with make_client(url, key) as client:
            if site is None:
                print_sites(_get(client, "/sites"), Console())
                return
            params = {} if as_of is None else {"as_of": as_of}
            body = _get(client, f"/sites/{site}/estimates", **params)
    except (ApiFailed, httpx.HTTPError) as exc:
        Console(stderr=True).print(f"[bold red]error[/]: {exc}", highlight=False)
        raise typer.Exit(code=1) from None
    print_estimates(body, Console())


@cli.command("rebuild-estimates")
def rebuild_estimates(
    check: Annotated[
        bool, typer.Option("--check", help="Only compare the table with the record")
    ] = False,
) -> None:
    """Recompute the site outcome table from the execution reports in the record."""
    from sqlalchemy.engine import make_url

    from app.sites import rebuild
    from app.store.db import make_engine, make_session_factory
    from app.store.lock import StoreInUseError, StoreLock
    from app.store.migrate import upgrade_head

    settings = get_settings()
    err = Console(stderr=True)
    url = make_url(settings.db_url)
    lock = None
    if url.get_backend_name() == "sqlite" and url.database:
        lock = StoreLock(Path(url.database))
        try:
            lock.acquire()
        except StoreInUseError as held:
            err.print(
                f"[bold red]error[/]: a server holds the store ({held}); stop it, then run "
                "ltaa rebuild-estimates again",
                highlight=False,
            )
            raise typer.Exit(code=1) from None
    try:
        upgrade_head(settings.db_url)
        engine = make_engine(settings.db_url)
        try:
            sessions = make_session_factory(engine)
            if check:
                found = rebuild.compare(sessions=sessions)
                typer.echo(
                    f"{found.stored} row(s) stored, {found.rebuilt} implied by the record: "
                    f"{'they agree' if found.agree else 'they differ'} (missing "
                    f"{len(found.missing)}, extra {len(found.extra)}, different "
                    f"{len(found.different)})"
                )
                raise typer.Exit(code=0 if found.agree else 1)
            count = rebuild.rebuild(sessions=sessions)
        finally:
            engine.dispose()
    finally:
        if lock is not None:
            lock.release()
    typer.echo(f"rebuilt the site outcome table from the record: {count} report(s)")
