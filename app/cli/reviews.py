"""`ltaa reviews` and `ltaa review`: a supervisor's review queue, over the HTTP API of a
running server (the server owns its data directory, so the CLI talks to it, not to it).

The server and key come from `--url` / `LTAA_URL` and `--key` / `LTAA_API_KEY` (a
supervisor key; omit it when the server runs without keys).
"""

from __future__ import annotations

from typing import Any

import httpx
from rich.console import Console
from rich.table import Table

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
) -> dict[str, Any]:
    body: dict[str, Any] = {"action": "override" if override else "approve"}
    if override:
        body["robot"] = override
    if reason:
        body["reason"] = reason
    response = client.post(f"/runs/{run_id}/reviews/{task_index}", json=body)
    if response.status_code != 200:
        raise ApiFailed(response)
    resolved: dict[str, Any] = response.json()
    return resolved


def _pct(x: float) -> str:
    return f"{x * 100:.1f}%"


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
        proposal = f"{p['robot']} {_pct(p['success'])}" + (
            " [yellow]fallback[/]" if p["fallback"] else ""
        )
        alternatives = "\n".join(
            f"{a['robot']}: {_pct(a['success'])}, load {a['load']}, "
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
