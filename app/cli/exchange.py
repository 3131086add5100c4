"""`ltaa import FILE`: a site's MS Project (MSPDI) or Primavera P6 (XER) file as a draft
instance, printed as JSON (docs/exchange.md).

Read here, by app.exchange, with no server: the same draft POST /schedules/import answers.
`--site` fills the robots' rates from a site's learned estimates, which live on a server:
they are read over its API (`--url` / `LTAA_URL`, `--key` / `LTAA_API_KEY`, a client key
will do), like `ltaa estimates`.
"""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import httpx
import typer
from rich.console import Console
from rich.markup import escape

from app.cli.reviews import ApiFailed, make_client
from app.cli.root import _URL, cli
from app.config import get_settings
from app.exchange import Draft, ExchangeError, fill_rates, read_schedule


class FileFormat(StrEnum):
    MSPDI = "mspdi"
    XER = "xer"


def _error(message: str) -> typer.Exit:
    Console(stderr=True).print(f"[bold red]error[/] {escape(message)}", highlight=False)
    return typer.Exit(code=1)


def site_rates(url: str, key: str | None, site: str) -> dict[str, dict[str, float]]:
    """{robot: {feature: posterior mean}} from GET /sites/{site}/estimates."""
    with make_client(url, key) as client:
        answer = client.get(f"/sites/{site}/estimates")
    if answer.status_code != 200:
        raise ApiFailed(answer)
    body: dict[str, Any] = answer.json()
    return {
        r["robot"]: {f["feature"]: f["posterior_mean"] for f in r["features"]}
        for r in body["robots"]
    }


@cli.command("import")
def import_file(
    path: Annotated[
        Path,
        typer.Argument(help="An MS Project XML (MSPDI) file or a Primavera P6 XER export"),
    ],
    format_: Annotated[
        FileFormat | None,
        typer.Option("--format", help="mspdi or xer [default: told by the file's first bytes]"),
    ] = None,
    features_field: Annotated[
        str | None,
        typer.Option(
            help="The field holding each task's features, comma-separated (Text1 or its "
            "alias, a P6 user field or activity code) [default: Features, else Text1]",
            show_default=False,
        ),
    ] = None,
    default_features: Annotated[
        str | None,
        typer.Option(
            help="Comma-separated features for tasks without any (else they are skipped)",
            show_default=False,
        ),
    ] = None,
    site: Annotated[
        str | None,
        typer.Option(
            help="Fill the robots' rates from this site's learned estimates (read from the "
            "server at --url)",
            show_default=False,
        ),
    ] = None,
    url: _URL = "http://127.0.0.1:8000",
    key: Annotated[
        str | None,
        typer.Option("--key", envvar="LTAA_API_KEY", help="A client API key", show_default=False),
    ] = None,
) -> None:
    """Print a schedule file as a draft instance (tasks, robots, start, source, skipped)."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise _error(f"cannot read {path}: {exc.strerror or exc}") from None
    limit = get_settings().import_max_bytes
    if len(data) > limit:
        raise _error(
            f"{path} is {len(data):,} bytes: the limit is {limit:,} (LTAA_IMPORT_MAX_BYTES); "
            "raise it for a file that size"
        )
    try:
        draft: Draft = read_schedule(
            data,
            format=None if format_ is None else format_.value,
            features_field=features_field,
            default_features=default_features,
        )
    except ExchangeError as exc:
        raise _error(f"{exc.field or 'file'}: {exc.message}") from None
    if site is not None:
        try:
            rates = site_rates(url, key, site)
        except (ApiFailed, httpx.HTTPError) as exc:
            raise _error(f"site {site}: {exc}") from None
        draft = fill_rates(draft, rates, site=site)
    typer.echo(json.dumps(draft.to_dict(), indent=2))
