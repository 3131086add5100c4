"""`ltaa backup` and `ltaa restore`: the embedded store's files, consistent, while it runs.

A server holding the store (its process lock) is asked to take the backup itself
(POST /admin/backup), since only it can hold its runs at a node boundary; with no server,
this process takes the lock, so none can start meanwhile, and copies the files directly.
"""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Any

import httpx
import typer
from rich.console import Console

from app.cli.root import cli
from app.config import Settings, get_settings
from app.operations import backup
from app.store.lock import StoreInUseError, StoreLock, listen_url


class StoreCommandError(RuntimeError):
    """A backup or restore that could not be made; the message says why and what to do."""


def _server_url(settings: Settings, url: str | None, held: StoreInUseError) -> str:
    """Where the server holding the store answers: --url, else the address its lock file
    records, else the configured one."""
    return url or held.holder.url or listen_url(settings.host, settings.port)


def _server_backup(settings: Settings, dest: Path, base: str, api_key: str | None) -> Any:
    key = api_key or os.environ.get("LTAA_API_KEY")
    headers = {"Authorization": f"Bearer {key}"} if key else {}
    try:
        answer = httpx.post(
            f"{base}/admin/backup", json={"dest": str(dest)}, headers=headers, timeout=600
        )
    except httpx.HTTPError as exc:
        raise StoreCommandError(
            f"a server holds the store but did not answer at {base} ({exc}); pass --url"
        ) from None
    if answer.status_code != 200:
        detail = answer.json().get("detail", answer.text) if answer.content else answer.text
        raise StoreCommandError(f"the server refused the backup ({answer.status_code}): {detail}")
    return answer.json()


def run_backup(
    settings: Settings, dest: Path, *, url: str | None = None, api_key: str | None = None
) -> tuple[dict[str, Any], str]:
    """(the backup's manifest, "server" or "direct")."""
    dest = dest.resolve()
    lock = StoreLock(backup.database_file(settings))
    try:
        lock.acquire()
    except StoreInUseError as held:
        return _server_backup(settings, dest, _server_url(settings, url, held), api_key), "server"
    try:
        report = backup.backup(settings=settings, dest=dest)
    finally:
        lock.release()
    return report.__dict__, "direct"


def run_restore(settings: Settings, source: Path) -> list[str]:
    lock = StoreLock(backup.database_file(settings))
    try:
        lock.acquire()
    except StoreInUseError as exc:
        raise StoreCommandError(f"cannot restore into a store in use: {exc}") from None
    try:
        return backup.restore(settings=settings, source=source)
    finally:
        lock.release()


def run_archive(
    settings: Settings,
    before: datetime,
    *,
    url: str | None = None,
    api_key: str | None = None,
    after_file: Callable[[str], None] | None = None,
) -> tuple[dict[str, Any], str]:
    """Archive through the server holding the store, or directly under the store lock."""
    from app.operations import service
    from app.store.db import make_engine, make_session_factory
    from app.store.migrate import upgrade_head

    lock = StoreLock(backup.database_file(settings))
    try:
        lock.acquire()
    except StoreInUseError as held:
        base = _server_url(settings, url, held)
        key = api_key or os.environ.get("LTAA_API_KEY")
        headers = {"Authorization": f"Bearer {key}"} if key else {}
        answer = httpx.post(
            f"{base}/admin/archive",
            json={"before": before.isoformat()},
            headers=headers,
            timeout=3600,
        )
        if answer.status_code != 200:
            raise StoreCommandError(
                f"the server refused the archive ({answer.status_code}): {answer.text}"
            ) from None
        return answer.json(), "server"
    try:
        upgrade_head(settings.db_url)
        engine = make_engine(settings.db_url)
        try:
            done = service.archive_finished(
                sessions=make_session_factory(engine),
                settings=settings,
                before=before,
                after_file=after_file,
            )
        finally:
            engine.dispose()
    finally:
        lock.release()
    return {
        "archive_dir": str(settings.archive_root),
        "lineages": [{"head": x.head, "runs": x.runs, "files": x.files} for x in done],
    }, "direct"


@cli.command("backup")
def backup_command(
    dest: Annotated[Path, typer.Argument(help="A new or empty directory for the copy")],
    url: Annotated[
        str | None,
        typer.Option(
            help="The server holding the store [default: the address it recorded in the "
            "store's lock file, else http://LTAA_HOST:LTAA_PORT]"
        ),
    ] = None,
    api_key: Annotated[
        str | None, typer.Option(help="A supervisor key [default: LTAA_API_KEY]")
    ] = None,
) -> None:
    """Back up the data directory's two SQLite files, consistent with each other, while the
    server runs (it holds its runs at a node boundary meanwhile)."""
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
