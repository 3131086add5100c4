"""The `ltaa` command line: `ltaa serve`, `ltaa allocate`. One function per command, so
further commands (`ltaa run`, `ltaa bench`) are added with another `@cli.command()`.
"""

from __future__ import annotations

import json
import os
import signal
from collections import defaultdict
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Any, NoReturn

import httpx
import typer
from pydantic import ValidationError
from rich.console import Console
from rich.table import Table

from app.api.allocation import allocate as run_allocation
from app.api.errors import domain_error_body, validation_error_body
from app.api.rounding import rounded
from app.api.schemas.allocation import AllocateRequest, AllocateResponse
from app.config import Settings, get_settings
from app.domain.errors import DomainError
from app.domain.lifecycle import RunStatus
from app.domain.modes import Mode
from app.reasoners.scope import LLMScope

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


@cli.command()
def serve(
    host: Annotated[str | None, typer.Option(help="Bind address [default: LTAA_HOST]")] = None,
    port: Annotated[int | None, typer.Option(help="Port [default: LTAA_PORT]")] = None,
) -> None:
    """Apply database migrations, then serve the HTTP API with uvicorn."""
    import uvicorn  # only this command needs the server

    if host is not None:
        # create_app reads LTAA_HOST to refuse an exposed address without API keys.
        os.environ["LTAA_HOST"] = host
    settings = get_settings()
    apply_migrations(settings)
    uvicorn.run(
        "app.main:create_app", factory=True, host=host or settings.host, port=port or settings.port
    )


@cli.command("reencrypt-webhook-secrets")
def reencrypt_webhook_secrets() -> None:
    """Re-encrypt every webhook secret under the first key of LTAA_SECRET_KEY (after a
    server key rotation: new key first, old key after it; then drop the old key)."""
    from app.store.db import make_engine, make_session_factory
    from app.webhooks.errors import SecretKeyError
    from app.webhooks.secret_box import SecretBox
    from app.webhooks.service import reencrypt_secrets

    settings = get_settings()
    apply_migrations(settings)
    raw = settings.secret_key.get_secret_value() if settings.secret_key else None
    engine = make_engine(settings.db_url)
    try:
        box = SecretBox.from_setting(raw, settings.data_dir)
        count = reencrypt_secrets(sessions=make_session_factory(engine), box=box)
    except SecretKeyError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    finally:
        engine.dispose()
    typer.echo(f"re-encrypted {count} webhook secret(s) under the first key")


def apply_migrations(settings: Settings) -> None:
    """Bring the database to the latest schema before serving (never at import)."""
    from app.store.migrate import upgrade_head  # alembic loads only for this command

    settings.data_dir.mkdir(parents=True, exist_ok=True)  # SQLite will not create parent dirs
    upgrade_head(settings.db_url)


@cli.command()
def allocate(
    solver: Annotated[str, typer.Option(help="Solver name (see GET /solvers)")] = "optimal",
    scenario: Annotated[str, typer.Option(help="Built-in scenario")] = "baseline",
    instance: Annotated[
        Path | None,
        typer.Option(
            help="JSON file with your own 'tasks' and 'robots' (replaces --scenario)",
            exists=True,
            dir_okay=False,
        ),
    ] = None,
    mode: Annotated[Mode, typer.Option(help="Operational mode")] = Mode.BALANCED,
    max_deviation: Annotated[
        float | None,
        typer.Option(help="Workload cap, in tasks either side of the target (default: the mode's)"),
    ] = None,
    seed: Annotated[int, typer.Option(help="Random seed")] = 0,
    option: Annotated[
        list[str] | None,
        typer.Option(
            "--option", "-o", help="Solver option KEY=VALUE (VALUE parsed as JSON); repeatable"
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the API's JSON response")] = False,
    show_tasks: Annotated[bool, typer.Option(help="Also list every task's assignment")] = False,
) -> None:
    """Allocate a task queue with one solver and print the assignments and metrics."""
    body: dict[str, Any] = {
        "solver": solver,
        "mode": mode.value,
        "seed": seed,
        "options": _parse_options(option or []),
    }
    if max_deviation is not None:
        body["max_deviation"] = max_deviation
    if instance is None:
        body["scenario"] = scenario
    else:
        body.update(_read_instance(instance, as_json))
    try:
        response = run_allocation(AllocateRequest.model_validate(body), get_settings())
    except ValidationError as exc:
        _fail(validation_error_body(exc.errors(include_input=False), root=("body",)), as_json)
    except DomainError as exc:
        _fail(domain_error_body(exc), as_json)
    if as_json:
        # Rounded as the API rounds, so the two print the same document.
        typer.echo(json.dumps(rounded(response.model_dump(mode="json")), indent=2))
    else:
        _print_report(response, show_tasks=show_tasks)


def _parse_options(pairs: list[str]) -> dict[str, Any]:
    options: dict[str, Any] = {}
    for pair in pairs:
        key, sep, raw = pair.partition("=")
        if not sep or not key:
            raise typer.BadParameter(f"expected KEY=VALUE, got '{pair}'", param_hint="--option")
        try:
            options[key] = json.loads(raw)
        except json.JSONDecodeError:
            options[key] = raw  # bare words are strings: -o policy=greedy
    return options


def _read_instance(path: Path, as_json: bool) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        _fail(
            {
                "detail": [
                    {"loc": ["instance"], "msg": f"not valid JSON: {exc}", "type": "json_invalid"}
                ]
            },
            as_json,
        )
    if not isinstance(doc, dict):
        _fail(
            {
                "detail": [
                    {
                        "loc": ["instance"],
                        "msg": "expected a JSON object with 'tasks' and 'robots'",
                        "type": "model_type",
                    }
                ]
            },
            as_json,
        )
    return {key: doc[key] for key in ("tasks", "robots") if key in doc}


def _fail(body: dict[str, Any], as_json: bool) -> NoReturn:
    """Report an invalid request the way the API would (same JSON under --json) and exit 1."""
    if as_json:
        typer.echo(json.dumps(body, indent=2))
    else:
        err = Console(stderr=True)
        for item in body["detail"]:
            where = ".".join(str(p) for p in item["loc"][1:]) or "request"
            err.print(f"[bold red]error[/] [cyan]{where}[/]: {item['msg']}", highlight=False)
    raise typer.Exit(code=1)


def _print_report(r: AllocateResponse, *, show_tasks: bool) -> None:
    console = Console()  # made per call: tests swap sys.stdout
    m = r.metrics
    cap = "no cap" if r.max_deviation is None else f"cap ±{r.max_deviation:g} tasks"
    console.print(
        f"[bold]{r.solver}[/] · {r.mode.value} · {cap} · {len(r.assignments)} tasks · "
        f"{r.elapsed_ms:.1f} ms"
    )

    by_robot: dict[str, list[float]] = defaultdict(list)
    names: dict[str, list[str]] = defaultdict(list)
    for a in r.assignments:
        by_robot[a.robot].append(a.success)
        names[a.robot].append(a.task_name)
    robots = Table(title="Assignments by robot")
    for col in ("Robot", "Tasks", "Mean success", "Assigned"):
        robots.add_column(col, justify="right" if col in ("Tasks", "Mean success") else "left")
    for robot, load in m.workload.items():
        scores = by_robot.get(robot, [])
        mean = f"{sum(scores) / len(scores):.3f}" if scores else "-"
        shown = ", ".join(names[robot][:6]) + (", …" if len(names[robot]) > 6 else "")
        robots.add_row(robot, str(load), mean, shown)
    console.print(robots)

    if show_tasks:
        tasks = Table(title="Assignments in queue order")
        for col in ("#", "Task id", "Task", "Robot", "Success"):
            tasks.add_column(col)
        for i, a in enumerate(r.assignments):
            tasks.add_row(str(i), str(a.task_id), a.task_name, a.robot, f"{a.success:.3f}")
        console.print(tasks)

    metrics = Table(title="Metrics")
    metrics.add_column("Metric")
    metrics.add_column("Value", justify="right")
    sim = m.simulated_completion
    rows = [
        ("Expected success", f"{m.expected_success:.6f} ({m.expected_success:.1%})"),
        ("Balance score", f"{m.balance_score:.1f} / 100"),
        ("Max deviation", f"{m.max_deviation:g} tasks"),
        ("Imbalance severity", m.imbalance_severity),
        ("Jain index", f"{m.jain_index:.4f}"),
        (
            "Simulated completion",
            f"{sim.mean:.4f} (95% CI {sim.ci95[0]:.4f}–{sim.ci95[1]:.4f}, {sim.trials} trials)",
        ),
        *((f"Success on {f}", f"{v:.4f}") for f, v in m.feature_success.items()),
    ]
    if r.usage.llm_calls:
        rows.append(
            (
                "LLM calls / tokens in / out",
                f"{r.usage.llm_calls} / {r.usage.input_tokens} / {r.usage.output_tokens}",
            )
        )
    for name, value in rows:
        metrics.add_row(name, value)
    console.print(metrics)


@cli.command()
def run(
    scenario: Annotated[str, typer.Option(help="Built-in scenario")] = "baseline",
    mode: Annotated[Mode, typer.Option(help="Operational mode")] = Mode.BALANCED,
    reasoner: Annotated[
        str, typer.Option(help="'rules' (offline), 'anthropic' or 'openai'")
    ] = "rules",
    max_deviation: Annotated[
        float | None,
        typer.Option(help="Workload cap, in tasks either side of the target (default: the mode's)"),
    ] = None,
    guidance: Annotated[
        str | None,
        typer.Option(help="'optimizer' to give the reasoner the optimal completion's choice"),
    ] = None,
    llm_scope: Annotated[
        LLMScope,
        typer.Option(help="'contested': ask an LLM reasoner only for contested decisions"),
    ] = LLMScope.ALL,
) -> None:
    """Run the LTAA graph durably in the local data directory, with a progress bar."""
    from app.cli.runs import print_summary, run_locally
    from app.store.lock import StoreInUseError

    console = Console()
    try:
        view = run_locally(
            get_settings(),
            scenario=scenario,
            mode=mode,
            reasoner=reasoner,
            max_deviation=max_deviation,
            guidance=guidance,
            console=console,
            llm_scope=llm_scope.value,
        )
    except DomainError as exc:
        _fail(domain_error_body(exc), as_json=False)
    except StoreInUseError as exc:  # a server (or another `ltaa run`) has the data directory
        Console(stderr=True).print(f"[bold red]error[/]: {exc}", highlight=False)
        raise typer.Exit(code=1) from None
    print_summary(view, console)
    if view.run.status != RunStatus.COMPLETED:
        raise typer.Exit(1)


@cli.command("backup")
def backup_command(
    dest: Annotated[Path, typer.Argument(help="A new or empty directory for the copy")],
    url: Annotated[
        str | None,
        typer.Option(help="The server holding the store [default: http://LTAA_HOST:LTAA_PORT]"),
    ] = None,
    api_key: Annotated[
        str | None, typer.Option(help="A supervisor key [default: LTAA_API_KEY]")
    ] = None,
) -> None:
    """Back up the data directory's two SQLite files, consistent with each other, while the
    server runs (it holds its runs at a node boundary meanwhile)."""
    from app.cli.store import StoreCommandError, run_backup
    from app.operations.backup import BackupError

    try:
        manifest, how = run_backup(get_settings(), dest, url=url, api_key=api_key)
    except (StoreCommandError, BackupError) as exc:
        Console(stderr=True, soft_wrap=True).print(f"[bold red]error[/]: {exc}", highlight=False)
        raise typer.Exit(code=1) from None
    typer.echo(json.dumps({"taken_by": how, **manifest}, indent=2))


@cli.command("restore")
def restore_command(
    source: Annotated[Path, typer.Argument(help="A directory written by `ltaa backup`")],
) -> None:
    """Fill an empty data directory (LTAA_DATA_DIR) from a backup; then start the server
    there: runs that were running resume from the backup's point."""
    from app.cli.store import StoreCommandError, run_restore
    from app.operations.backup import BackupError

    try:
        written = run_restore(get_settings(), source)
    except (StoreCommandError, BackupError) as exc:
        Console(stderr=True, soft_wrap=True).print(f"[bold red]error[/]: {exc}", highlight=False)
        raise typer.Exit(code=1) from None
    for path in written:
        typer.echo(f"restored {path}")


@cli.command("archive")
def archive_command(
    before: Annotated[
        datetime,
        typer.Option(
            help="Archive lineages whose head completed or was cancelled before this date",
            formats=["%Y-%m-%d", "%Y-%m-%dT%H:%M:%S"],
        ),
    ],
    url: Annotated[str | None, typer.Option(help="The server holding the store")] = None,
    api_key: Annotated[
        str | None, typer.Option(help="A supervisor key [default: LTAA_API_KEY]")
    ] = None,
) -> None:
    """Archive old runs: verified JSON-lines files in LTAA_ARCHIVE_DIR, their rows deleted,
    tombstones left (lookups answer 410 naming the file), then VACUUM."""
    from app.cli.store import StoreCommandError, run_archive
    from app.operations.backup import BackupError

    when = before if before.tzinfo is not None else before.replace(tzinfo=UTC)
    # Test seam: die (SIGKILL) after this many archive files are in place.
    kill_after = int(os.environ.get("LTAA_TEST_ARCHIVE_KILL_AFTER", "0"))
    written: list[str] = []

    def after_file(run_id: str) -> None:
        written.append(run_id)
        if kill_after and len(written) >= kill_after:
            os.kill(os.getpid(), signal.SIGKILL)

    try:
        result, how = run_archive(
            get_settings(), when, url=url, api_key=api_key, after_file=after_file
        )
    except (StoreCommandError, BackupError) as exc:
        Console(stderr=True, soft_wrap=True).print(f"[bold red]error[/]: {exc}", highlight=False)
        raise typer.Exit(code=1) from None
    typer.echo(json.dumps({"done_by": how, **result}, indent=2))


@cli.command("keygen")
def keygen_command(
    path: Annotated[Path, typer.Argument(help="Where to write the private key (PEM, 0600)")],
) -> None:
    """Write a new Ed25519 signing key for signed chain heads; point LTAA_SIGNING_KEY_FILE
    at it. Keep the previous key's public half in LTAA_RETIRED_PUBLIC_KEYS_DIR."""
    from app.audit.signing import generate_key_file

    try:
        kid = generate_key_file(path)
    except FileExistsError:
        Console(stderr=True, soft_wrap=True).print(
            f"[bold red]error[/]: {path} exists; a key is never overwritten", highlight=False
        )
        raise typer.Exit(code=1) from None
    typer.echo(f"wrote {path} (key id {kid})")


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
    """Revise a run on a server (SPEC 10) and print the diff against its parent."""
    from app.cli.revise import ReviseError, build_changes, parse_pin, print_diff
    from app.cli.revise import revise as post_revision

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
            ),
            "pin": parse_pin(pin),
            "reason": reason,
        }
        if reasoner is not None:
            body["reasoner"] = reasoner
        created, diff = post_revision(url=url, api_key=api_key, run_id=run_id, body=body, wait=wait)
    except ReviseError as exc:
        Console(stderr=True).print(f"[bold red]error[/]: {exc}", highlight=False)
        raise typer.Exit(code=1) from None
    print_diff(created, diff, console)


@cli.command()
def bench(
    section: Annotated[
        list[str] | None,
        typer.Argument(help="Only these benchmark modules (e.g. benchmarks.solvers)"),
    ] = None,
) -> None:
    """Measure every method and write docs/benchmarks.md and docs/img/*.png."""
    from benchmarks.report import main as write_report

    write_report(section or None)


@cli.command("bench-llm")
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
    from benchmarks import llm_live

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


_URL = Annotated[
    str,
    typer.Option("--url", envvar="LTAA_URL", help="The server [default: http://127.0.0.1:8000]"),
]
_KEY = Annotated[
    str | None,
    typer.Option("--key", envvar="LTAA_API_KEY", help="A supervisor API key", show_default=False),
]


@cli.command()
def reviews(url: _URL = "http://127.0.0.1:8000", key: _KEY = None) -> None:
    """List the decisions waiting for a supervisor's review (GET /reviews)."""
    from app.cli.reviews import ApiFailed, make_client, pending, print_reviews

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
        str | None, typer.Option("--reason", help="Why (required with --override)")
    ] = None,
    url: _URL = "http://127.0.0.1:8000",
    key: _KEY = None,
) -> None:
    """Resolve a review: --approve, or --override ROBOT --reason TEXT."""
    from app.cli.reviews import ApiFailed, make_client, resolve

    if approve == (override is not None):
        raise typer.BadParameter("give exactly one of --approve and --override ROBOT")
    if override is not None and not (reason or "").strip():
        raise typer.BadParameter("--override needs --reason", param_hint="--reason")
    try:
        with make_client(url, key) as client:
            done = resolve(client, run_id, task_index, override=override, reason=reason)
    except (ApiFailed, httpx.HTTPError) as exc:
        Console(stderr=True).print(f"[bold red]error[/]: {exc}", highlight=False)
        raise typer.Exit(code=1) from None
    what = f"overridden to {done['robot']}" if done["action"] == "override" else "approved"
    typer.echo(
        f"task {task_index} of run {run_id} {what} by {done['reviewer']}; the run is "
        f"{done['status']} again"
    )


@cli.command("key-name")
def key_name(
    key: Annotated[str, typer.Argument(help="An API key of LTAA_API_KEYS (without :ROLE)")],
) -> None:
    """Print a key's fingerprint: its default name, and how LTAA_API_KEY_NAMES names it."""
    from app.api.auth import key_fingerprint

    typer.echo(key_fingerprint(key))


def main() -> None:
    cli()
