"""`ltaa revise`: revise a run on a running server when the site changes, then print the
diff against its parent with rich. Talks HTTP (the run lives in the server's store)."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Annotated, Any

import httpx
import typer
from rich.console import Console
from rich.table import Table

from app.cli.root import cli


class ReviseError(RuntimeError):
    """The server refused the revision (or could not be reached): the message says why."""


def parse_pin(text: str) -> str | dict[str, Any]:
    """'reported' | 'decided' | 'through:17' | 'tasks:a,b'."""
    if text in ("reported", "decided"):
        return text
    kind, _, rest = text.partition(":")
    if kind == "through" and rest.isdigit():
        return {"through_task_index": int(rest)}
    if kind == "tasks" and rest:
        return {"task_ids": [int(t) if t.isdigit() else t for t in rest.split(",")]}
    raise ReviseError(
        f"--pin {text!r}: write reported, decided, through:<task index> or tasks:<id,id,...>"
    )


def parse_rate(text: str) -> tuple[str, str, float]:
    """'light:heavy=0.95' -> (robot, feature, rate)."""
    robot, _, rest = text.partition(":")
    feature, _, value = rest.partition("=")
    try:
        return robot, feature, float(value)
    except ValueError:
        raise ReviseError(f"--set-rate {text!r}: write <robot>:<feature>=<rate>") from None


def parse_task(text: str) -> dict[str, Any]:
    """'U1:heavy,careful' -> a task needing those features."""
    task_id, _, features = text.partition(":")
    if not task_id or not features:
        raise ReviseError(f"--add-task {text!r}: write <id>:<feature>[,<feature>...]")
    return {"id": task_id, "features": features.split(",")}


def parse_delay(text: str) -> dict[str, Any]:
    """'21:30' -> task 21 takes 30 minutes longer (docs/living-plans.md#a-revision-in-time)."""
    task_id, _, minutes = text.rpartition(":")
    try:
        value = float(minutes)
    except ValueError:
        value = 0.0
    if not task_id or value <= 0:
        raise ReviseError(f"--delay {text!r}: write <task id>:<minutes>, minutes above 0")
    return {
        "type": "delay",
        "task_id": int(task_id) if task_id.isdigit() else task_id,
        "minutes": int(value) if value.is_integer() else value,
    }


def build_changes(
    *,
    unavailable: list[str],
    available: list[str],
    rates: list[str],
    add_next: list[str],
    add_end: list[str],
    remove: list[str],
    mode: str | None,
    max_deviation: float | None,
    delays: Sequence[str] = (),
) -> list[dict[str, Any]]:
    changes: list[dict[str, Any]] = [{"type": "robot_unavailable", "robot": r} for r in unavailable]
    changes += [{"type": "robot_available", "robot": r} for r in available]
    by_robot: dict[str, dict[str, float]] = {}
    for text in rates:
        robot, feature, value = parse_rate(text)
        by_robot.setdefault(robot, {})[feature] = value
    changes += [{"type": "set_rates", "robot": r, "success": s} for r, s in by_robot.items()]
    if add_next:
        changes.append(
            {"type": "add_tasks", "tasks": [parse_task(t) for t in add_next], "position": "next"}
        )
    if add_end:
        changes.append(
            {"type": "add_tasks", "tasks": [parse_task(t) for t in add_end], "position": "end"}
        )
    if remove:
        changes.append(
            {"type": "remove_tasks", "task_ids": [int(t) if t.isdigit() else t for t in remove]}
        )
    if mode is not None or max_deviation is not None:
        change: dict[str, Any] = {"type": "set_mode", "mode": mode or "balanced"}
        if max_deviation is not None:
            change["max_deviation"] = max_deviation
        changes.append(change)
    changes += [parse_delay(d) for d in delays]
    return changes


def _check(response: httpx.Response) -> dict[str, Any]:
    if response.status_code >= 400:
        try:
            detail = response.json()["detail"]
            message = "; ".join(f"{'.'.join(str(p) for p in d['loc'])}: {d['msg']}" for d in detail)
        except (ValueError, KeyError, TypeError):
            message = response.text
        raise ReviseError(f"HTTP {response.status_code}: {message}")
    return dict(response.json())


def post_revision(
    *,
    url: str,
    api_key: str | None,
    run_id: str,
    body: dict[str, Any],
    wait: bool,
    timeout: float = 600.0,
) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """(the revision as created, its diff once it completed; None without waiting)."""
    headers = {"X-API-Key": api_key} if api_key else {}
    with httpx.Client(base_url=url, headers=headers, timeout=30) as client:
        try:
            created = _check(client.post(f"/runs/{run_id}/revisions", json=body))
        except httpx.HTTPError as exc:
            raise ReviseError(f"cannot reach {url}: {exc}") from None
        if not wait:
            return created, None
        deadline = time.monotonic() + timeout
        while True:
            state = _check(client.get(f"/runs/{created['id']}"))
            if state["status"] == "completed":
                break
            if state["status"] in ("failed", "cancelled", "superseded"):
                raise ReviseError(f"revision {created['id']} ended {state['status']}")
            if time.monotonic() > deadline:
                raise ReviseError(f"revision {created['id']} still {state['status']}")
            time.sleep(0.2)
        return created, _check(client.get(f"/runs/{created['id']}/diff"))


def print_diff(created: dict[str, Any], diff: dict[str, Any] | None, console: Console) -> None:
    console.print(
        f"[bold]revision {created['revision']}[/] [cyan]{created['id']}[/] of "
        f"[cyan]{created['revision_of']}[/]: {created['status']}"
    )
    if diff is None:
        return
    summary = Table(title="Before and after", show_header=True)
    summary.add_column("")
    summary.add_column("parent", justify="right")
    summary.add_column("revision", justify="right")
    before, after = diff["before"], diff["after"]

    def pct(value: float | None) -> str:
        return "-" if value is None else f"{value * 100:.2f}%"

    def score(value: float | None) -> str:
        return "-" if value is None else f"{value:.1f}"

    summary.add_row(
        "expected success", pct(before["expected_success"]), pct(after["expected_success"])
    )
    summary.add_row("balance score", score(before["balance_score"]), score(after["balance_score"]))
    summary.add_row(
        "decided", f"{before['decided']}/{before['total']}", f"{after['decided']}/{after['total']}"
    )
    console.print(summary)
    if diff["fleet_changes"]:
        console.print(
            "fleet: " + ", ".join(f"{c['robot']} {c['change']}" for c in diff["fleet_changes"])
        )
    if diff["added_tasks"] or diff["removed_tasks"]:
        console.print(
            f"tasks added: {diff['added_tasks'] or '-'}; removed: {diff['removed_tasks'] or '-'}"
        )
    moved = Table(title=f"{len(diff['robot_changes'])} task(s) moved to another robot")
    for column in ("task", "name", "from", "to", "success before", "success after"):
        moved.add_column(column)
    for c in diff["robot_changes"]:
        moved.add_row(
            str(c["task_id"]),
            c["task_name"],
            held_by(c, "from"),
            held_by(c, "to"),
            pct(c["success_before"]),
            pct(c["success_after"]),
        )
    console.print(moved)
    if diff.get("schedule"):
        print_time_moves(diff["schedule"], console)


def held_by(change: dict[str, Any], side: str) -> str:
    """The robot, or a team task's members (docs/living-plans.md#teams-in-a-revision)."""
    team = change.get(f"{side}_team")
    return " + ".join(m["robot"] for m in team) if team else str(change[f"{side}_robot"])


def print_time_moves(schedule: dict[str, Any], console: Console) -> None:
    """docs/living-plans.md#the-diff-in-time: the makespans and each task that starts or ends at
    another time."""

    def minute(value: dict[str, Any]) -> str:
        return f"{value['minutes']:g} min ({value['at'] or '-'})"

    console.print(
        f"makespan: {minute(schedule['makespan_before'])} -> {minute(schedule['makespan_after'])}"
    )
    moves = Table(title=f"{len(schedule['moves'])} task(s) moved in time")
    for column in ("task", "name", "robot", "start", "end", "moved (min)"):
        moves.add_column(column)
    for m in schedule["moves"]:
        robot = m["robot_after"]
        if m["robot_before"] != robot:
            robot = f"{m['robot_before']} -> {robot}"
        moves.add_row(
            str(m["task_id"]),
            m["task_name"],
            robot,
            f"{m['start_before']:g} -> {m['start_after']:g}",
            f"{m['end_before']:g} -> {m['end_after']:g}",
            f"{m['start_moved']:+g} / {m['end_moved']:+g}",
        )
    console.print(moves)


@cli.command()
def revise(
    run_id: Annotated[str, typer.Argument(help="The run to revise (the head of its lineage)")],
    robot_unavailable: Annotated[
        list[str] | None, typer.Option(help="Robot that takes no new task (repeatable)")
    ] = None,
    robot_available: Annotated[
        list[str] | None, typer.Option(help="Robot back in service (repeatable)")
    ] = None,
    set_rate: Annotated[
        list[str] | None, typer.Option(help="<robot>:<feature>=<rate>, e.g. light:heavy=0.9")
    ] = None,
    add_task_next: Annotated[
        list[str] | None, typer.Option(help="<id>:<feature,...> placed right after the pins")
    ] = None,
    add_task: Annotated[
        list[str] | None, typer.Option(help="<id>:<feature,...> placed at the end")
    ] = None,
    remove_task: Annotated[list[str] | None, typer.Option(help="Task id to drop")] = None,
    mode: Annotated[str | None, typer.Option(help="New operational mode")] = None,
    max_deviation: Annotated[float | None, typer.Option(help="New workload cap")] = None,
    delay: Annotated[
        list[str] | None,
        typer.Option(help="<task id>:<minutes> the task takes longer (timed runs; repeatable)"),
    ] = None,
    now: Annotated[
        str | None,
        typer.Option(help="Plan from this RFC 3339 time (timed runs; default: the arrival)"),
    ] = None,
    pin: Annotated[
        str, typer.Option(help="reported | decided | through:<task index> | tasks:<id,...>")
    ] = "reported",
    reason: Annotated[str, typer.Option(help="Why the plan changes (kept in the record)")] = (
        "site change"
    ),
    reasoner: Annotated[str | None, typer.Option(help="Override the inherited reasoner")] = None,
    url: Annotated[str, typer.Option(help="The server", envvar="LTAA_URL")] = (
        "http://127.0.0.1:8000"
    ),
    api_key: Annotated[
        str | None, typer.Option(help="Client API key", envvar="LTAA_CLIENT_API_KEY")
    ] = None,
    wait: Annotated[bool, typer.Option(help="Wait for the revision and print the diff")] = True,
) -> None:
    """Revise a run on a server (docs/living-plans.md#the-lineage-and-the-diff) and print the diff
    against its parent."""

    console = Console()
    try:
        body: dict[str, Any] = {
            "changes": build_changes(
                unavailable=robot_unavailable or [],
                available=robot_available or [],
                rates=set_rate or [],
                add_next=add_task_next or [],
                add_end=add_task or [],
                remove=remove_task or [],
                mode=mode,
                max_deviation=max_deviation,
                delays=delay or [],
            ),
            "pin": parse_pin(pin),
            "reason": reason,
        }
        if reasoner is not None:
            body["reasoner"] = reasoner
        if now is not None:
            body["now"] = now
        created, diff = post_revision(url=url, api_key=api_key, run_id=run_id, body=body, wait=wait)
    except ReviseError as exc:
        Console(stderr=True).print(f"[bold red]error[/]: {exc}", highlight=False)
        raise typer.Exit(code=1) from None
    print_diff(created, diff, console)
