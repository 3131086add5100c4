"""One process per embedded (SQLite) store.

The single-process worker treats every run it finds `running` at start-up as orphaned and
resumes it. A second process on the same SQLite files (say `ltaa serve` started while
`make run` is up) would therefore take over the first one's live runs and write a false
audit record, even if it then fails to bind its port: uvicorn runs the app's start-up
before it listens. An exclusive advisory lock next to the app database stops the second
process first. The kernel drops the lock when its holder dies, SIGKILL included, so a
restart after a crash is never blocked.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path
from typing import IO


class StoreInUseError(RuntimeError):
    """Another live process holds the embedded store."""


class StoreLock:
    def __init__(self, database_file: Path) -> None:
        self.path = database_file.with_name(database_file.name + ".lock")
        self._file: IO[str] | None = None

    def acquire(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        handle = self.path.open("a+")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "unknown"
            handle.close()
            raise StoreInUseError(
                f"another LTAA process (pid {holder}) is using {self.path.parent}: stop it "
                "first, or give this one its own LTAA_DATA_DIR. Two processes on one SQLite "
                "store would both resume the same runs; several processes need PostgreSQL "
                "(LTAA_DATABASE_URL)."
            ) from None
        handle.seek(0)
        handle.truncate()
        handle.write(str(os.getpid()))
        handle.flush()
        self._file = handle

    def release(self) -> None:
        if self._file is not None:
            fcntl.flock(self._file, fcntl.LOCK_UN)
            self._file.close()
            self._file = None
