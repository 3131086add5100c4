"""One process per embedded (SQLite) store.

The single-process worker treats every run it finds `running` at start-up as orphaned and
resumes it. A second process on the same SQLite files (say `ltaa serve` started while
`make run` is up) would therefore take over the first one's live runs and write a false
audit record, even if it then fails to bind its port: uvicorn runs the app's start-up
before it listens. An exclusive advisory lock next to the app database stops the second
process first. The kernel drops the lock when its holder dies, SIGKILL included, so a
restart after a crash is never blocked.

The lock file names its holder: its pid and, for a server, the address it listens on, so a
command that finds the store held (`ltaa backup`, `ltaa archive`) can ask that server to do
the work wherever it was started (`make run PORT=9000`).
"""

from __future__ import annotations

import fcntl
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import IO


@dataclass(frozen=True)
class Holder:
    """Who holds the store, as its lock file says."""

    pid: str
    url: str | None = None  # where it listens, if it is a server

    @classmethod
    def parse(cls, text: str) -> Holder:
        try:
            data = json.loads(text)
        except ValueError:
            data = None
        if isinstance(data, dict):
            url = data.get("url")
            return cls(
                pid=str(data.get("pid", "unknown")), url=url if isinstance(url, str) else None
            )
        # Lock files written before the address was recorded hold the pid alone.
        return cls(pid=text.strip() or "unknown")


def listen_url(host: str, port: int) -> str:
    """The URL a client on this machine reaches a server bound to host:port with."""
    if host in ("0.0.0.0", ""):
        host = "127.0.0.1"
    elif host == "::":
        host = "::1"
    if ":" in host and not host.startswith("["):
        host = f"[{host}]"
    return f"http://{host}:{port}"


class StoreInUseError(RuntimeError):
    """Another live process holds the embedded store."""

    def __init__(self, message: str, holder: Holder) -> None:
        super().__init__(message)
        self.holder = holder


class StoreLock:
    def __init__(self, database_file: Path) -> None:
        self.path = database_file.with_name(database_file.name + ".lock")
        self._file: IO[str] | None = None

    def acquire(self, url: str | None = None) -> None:
        """Hold the store, or raise StoreInUseError naming the holder. `url`: where this
        process serves the API, recorded for commands that find the store held."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        handle = self.path.open("a+")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = Holder.parse(handle.read())
            handle.close()
            where = f", serving {holder.url}" if holder.url else ""
            raise StoreInUseError(
                f"another LTAA process (pid {holder.pid}{where}) is using {self.path.parent}: "
                "stop it first, or give this one its own LTAA_DATA_DIR. Two processes on one "
                "SQLite store would both resume the same runs; several processes need "
                "PostgreSQL (LTAA_DATABASE_URL).",
                holder,
            ) from None
        handle.seek(0)
        handle.truncate()
        handle.write(json.dumps({"pid": os.getpid(), "url": url}))
        handle.flush()
        self._file = handle

    def release(self) -> None:
        if self._file is not None:
            fcntl.flock(self._file, fcntl.LOCK_UN)
            self._file.close()
            self._file = None
