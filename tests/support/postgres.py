"""A fresh PostgreSQL database per test module, on the server `LTAA_TEST_POSTGRES_URL` names.

CI provides the server, so an unreachable one fails the tests with a message saying how to
fix it; skipping would let the scale-out path go untested unnoticed.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from contextlib import contextmanager

import psycopg
import pytest
from psycopg import sql
from sqlalchemy.engine import make_url

from app.graph.checkpoint.postgres import libpq_url

DEFAULT_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/test"


def base_url() -> str:
    return os.environ.get("LTAA_TEST_POSTGRES_URL") or DEFAULT_URL


@contextmanager
def fresh_database(prefix: str = "ltaa_test") -> Iterator[str]:
    """Create a uniquely named database next to the configured one; drop it afterwards."""
    base = make_url(base_url())
    admin = libpq_url(base.render_as_string(hide_password=False))
    error: str | None
    try:
        conn = psycopg.connect(admin, autocommit=True, connect_timeout=5)
    except psycopg.Error as exc:
        error = str(exc).strip()
    else:
        error = None
    if error is not None:
        pytest.fail(
            f"PostgreSQL is not reachable at {base.render_as_string(hide_password=True)}: "
            f"{error}\nThese tests need a real server: start one, or set "
            "LTAA_TEST_POSTGRES_URL to a postgresql+psycopg:// URL whose user may "
            "CREATE DATABASE.",
            pytrace=False,
        )
    name = f"{prefix}_{uuid.uuid4().hex[:12]}"
    with conn:
        conn.execute(sql.SQL("CREATE DATABASE {}").format(sql.Identifier(name)))
        # A commit returns before its WAL record reaches the disk: the tests kill the app's
        # processes, never PostgreSQL, and a committed row is visible to every session at
        # once either way; parallel test workers no longer queue behind each other's fsyncs.
        conn.execute(
            sql.SQL("ALTER DATABASE {} SET synchronous_commit = off").format(sql.Identifier(name))
        )
    try:
        yield base.set(database=name).render_as_string(hide_password=False)
    finally:
        with psycopg.connect(admin, autocommit=True) as conn:
            # FORCE: a SIGKILLed server's connections may linger for a moment.
            conn.execute(
                sql.SQL("DROP DATABASE IF EXISTS {} WITH (FORCE)").format(sql.Identifier(name))
            )


def query(url: str, statement: str, *params: object) -> list[tuple[object, ...]]:
    """Run one statement on its own connection; its rows, if it returns any."""
    with psycopg.connect(libpq_url(url), autocommit=True) as conn:
        cur = conn.execute(statement, params)
        return list(cur.fetchall()) if cur.description is not None else []
