"""`ltaa backup` and `ltaa restore`: the embedded store's files, consistent, while it runs.

A server holding the store (its process lock) is asked to take the backup itself
(POST /admin/backup), since only it can hold its runs at a node boundary; with no server,
this process takes the lock, so none can start meanwhile, and copies the files directly.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

import httpx

from app.config import Settings
from app.operations import backup
from app.store.lock import StoreInUseError, StoreLock


class StoreCommandError(RuntimeError):
    """A backup or restore that could not be made; the message says why and what to do."""


def _server_backup(settings: Settings, dest: Path, url: str | None, api_key: str | None) -> Any:
    base = url or f"http://{settings.host}:{settings.port}"
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
    except StoreInUseError:
        return _server_backup(settings, dest, url, api_key), "server"
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
    from app.operations import archive
    from app.store.db import make_engine, make_session_factory
    from app.store.migrate import upgrade_head

    lock = StoreLock(backup.database_file(settings))
    try:
        lock.acquire()
    except StoreInUseError:
        base = url or f"http://{settings.host}:{settings.port}"
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
            sessions = make_session_factory(engine)
            dest = settings.archive_root
            done = archive.archive(
                sessions=sessions, before=before, dest=dest, after_file=after_file
            )
        finally:
            engine.dispose()
        if done:
            archive.vacuum(backup.database_file(settings))
    finally:
        lock.release()
    return {
        "archive_dir": str(dest),
        "lineages": [{"head": x.head, "runs": x.runs, "files": x.files} for x in done],
    }, "direct"
