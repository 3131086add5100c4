"""`ltaa reviews` and `ltaa review`: a supervisor's review queue, over the HTTP API of a
running server (the server owns its data directory, so the CLI talks to it, not to it).

The server and key come from `--url` / `LTAA_URL` and `--key` / `LTAA_API_KEY` (a
supervisor key; omit it when the server runs without keys).
"""

from __future__ import annotations

from typing import Annotated, Any

import httpx
import typer
from rich.console import Console
from rich.table import Table

from app.cli.root import _KEY, _URL, cli

DEFAULT_URL = "http://127.0.0.1:8000"


class ApiFailed(RuntimeError):
    """The server answered with an error; the message is its first `msg` and where."""

    def __init__(self, response: httpx.Response) -> None:
        try:
            item = response.json()["detail"][0]
            where = ".".join(str(p) for p in item.get("loc", []))
            text = f"{response.status_code}: {item['msg']} ({where})"
        except (ValueError, KeyError, IndexError, TypeError):
            text = f"{response.status_code}: {response.text[:200]}"
        super().__init__(text)
        self.status_code = response.status_code


def make_client(url: str, key: str | None) -> httpx.Client:
    headers = {"Authorization": f"Bearer {key}"} if key else {}
    return httpx.Client(base_url=url, headers=headers, timeout=30)


def pending(client: httpx.Client) -> list[dict[str, Any]]:
    response = client.get("/reviews")
    if response.status_code != 200:
        raise ApiFailed(response)
    reviews: list[dict[str, Any]] = response.json()
    return reviews


def resolve(
    client: httpx.Client,
    run_id: str,
    task_index: int,
    *,
    override: str | None,
    reason: str | None,
    team: list[dict[str, str]] | None = None,
) -> dict[str, Any]:
    body: dict[str, Any] = {"action": "override" if override or team else "approve"}
    if override:
        body["robot"] = override
    if team:
        body["team"] = team
    if reason:
        body["reason"] = reason
    response = client.post(f"/runs/{run_id}/reviews/{task_index}", json=body)
    if response.status_code != 200:
        raise ApiFailed(response)
    resolved: dict[str, Any] = response.json()
    return resolved


def _pct(x: float) -> str:
    return f"{x * 100:.1f}%"


def _who(entry: dict[str, Any]) -> str:
    """A robot, or a team's members (docs/reviews.md#reviews-of-team-decisions)."""
    return " + ".join(m["robot"] for m in entry.get("team") or [entry])


def parse_team(value: str) -> list[dict[str, str]]:
    """`--team crane:heavy,lifter:heavy`: robot:feature per unit (the feature after the last
    colon, so a robot name may hold one)."""
    out = []
    for part in value.split(","):
        robot, _, feature = part.strip().rpartition(":")
        if not robot or not feature:
            raise typer.BadParameter(f"'{part}' is not robot:feature", param_hint="--team")
        out.append({"robot": robot, "feature": feature})
    return out


def print_reviews(reviews: list[dict[str, Any]], console: Console) -> None:
    if not reviews:
        console.print("No decisions are waiting for review.")
        return
    table = Table(title=f"{len(reviews)} decision(s) waiting for review, oldest first")
    table.add_column("run", no_wrap=True)  # an id to copy into `ltaa review`
    for column in ("task", "proposal", "Q", "triggers", "alternatives", "requested"):
        table.add_column(column)
    for r in reviews:
        p = r["proposal"]
        proposal = f"{_who(p)} {_pct(p['success'])}" + (
            " [yellow]fallback[/]" if p["fallback"] else ""
        )
        alternatives = "\n".join(
            f"{_who(a)}: {_pct(a['success'])}, load {a['load']}, "
            + (
                f"regret {a['regret_if_chosen']:.1f} pts"
                if a["cap_feasible"]
                else "[red]breaks the cap[/]"
            )
            for a in r["alternatives"]
        )
        table.add_row(
            r["run_id"],
            f"{r['task_index']} ({r['task_id']}: {r['task_name']})",
            proposal,
            f"{p['quality']:.2f}",
            ", ".join(r["triggers"]),
            alternatives,
            r["requested_at"],
        )
    console.print(table)


@cli.command()
def reviews(url: _URL = "http://127.0.0.1:8000", key: _KEY = None) -> None:
    """List the decisions waiting for a supervisor's review (GET /reviews)."""

    try:
        with make_client(url, key) as client:
            found = pending(client)
    except (ApiFailed, httpx.HTTPError) as exc:
        Console(stderr=True).print(f"[bold red]error[/]: {exc}", highlight=False)
        raise typer.Exit(code=1) from None
    print_reviews(found, Console())


@cli.command()
def review(
    run_id: Annotated[str, typer.Argument(help="The run (see `ltaa reviews`)")],
    task_index: Annotated[int, typer.Argument(help="The task index waiting for review")],
    approve: Annotated[bool, typer.Option("--approve", help="Approve the proposal")] = False,
    override: Annotated[
        str | None, typer.Option("--override", help="Use this robot instead", show_default=False)
    ] = None,
    reason: Annotated[
        str | None, typer.Option("--reason", help="Why (required with --override or --team)")
    ] = None,
    team: Annotated[
        str | None,
        typer.Option(
            "--team",
            help="A team decision: use this team instead, robot:feature per unit "
            "(crane:heavy,lifter:heavy)",
            show_default=False,
        ),
    ] = None,
    url: _URL = "http://127.0.0.1:8000",
    key: _KEY = None,
) -> None:
    """Resolve a review: --approve, or --override ROBOT (a team decision: --team) --reason TEXT."""

    changes = override is not None or team is not None
    if approve == changes or (override is not None and team is not None):
        raise typer.BadParameter("give exactly one of --approve, --override ROBOT and --team")
    if changes and not (reason or "").strip():
        raise typer.BadParameter("--override and --team need --reason", param_hint="--reason")
    members = None if team is None else parse_team(team)
    try:
        with make_client(url, key) as client:
            done = resolve(
                client, run_id, task_index, override=override, reason=reason, team=members
            )
    except (ApiFailed, httpx.HTTPError) as exc:
        Console(stderr=True).print(f"[bold red]error[/]: {exc}", highlight=False)
        raise typer.Exit(code=1) from None
    what = f"overridden to {_who(done)}" if done["action"] == "override" else "approved"
    typer.echo(
        f"task {task_index} of run {run_id} {what} by {done['reviewer']}; the run is "
        f"{done['status']} again"
    )


@cli.command("key-name")
def key_name(
    key: Annotated[str, typer.Argument(help="An API key of LTAA_API_KEYS (without :ROLE)")],
) -> None:
    """Print a key's fingerprint: its default name, and how LTAA_API_KEY_NAMES names it."""
    from app.http.auth import key_fingerprint

    typer.echo(key_fingerprint(key))
