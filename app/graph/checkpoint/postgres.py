"""The LangGraph Postgres checkpointer over a psycopg pool, for the scale-out deployment.

Imported only when the database URL is PostgreSQL, so the embedded SQLite default never
loads psycopg (as LangGraph keeps its aiosqlite saver in `langgraph.checkpoint.sqlite.aio`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import psycopg
from langgraph.checkpoint.postgres import PostgresSaver
from psycopg.rows import dict_row
from psycopg_pool import ConnectionPool
from sqlalchemy.engine import make_url

from app.graph.checkpoint._pruning import PRUNE_EVERY, PruneSchedule, PruningPutMixin

__all__ = ["SETUP_LOCK_KEY", "PrunedPostgresSaver", "libpq_url", "open_postgres_saver"]

log = logging.getLogger("ltaa.runs")

# Shared by every process: replicas starting together must not race through setup()'s
# CREATE TABLE / INSERT INTO checkpoint_migrations steps.
SETUP_LOCK_KEY = 0x4C544143


def libpq_url(sqlalchemy_url: str) -> str:
    """`postgresql+psycopg://u:p@h/db` -> `postgresql://u:p@h/db` (what psycopg accepts)."""
    url = make_url(sqlalchemy_url).set(drivername="postgresql")
    return url.render_as_string(hide_password=False)


class PrunedPostgresSaver(PruningPutMixin, PostgresSaver):
    """PostgresSaver whose threads keep only their latest checkpoint (the saver's own
    `keep_latest` prune, safe while the thread appends) every PRUNE_EVERY checkpoints."""

    def __init__(
        self, conn: ConnectionPool[psycopg.Connection[dict[str, object]]], prune_every: int
    ) -> None:
        super().__init__(conn)
        self._schedule = PruneSchedule(prune_every)

    def prune_due(self, thread_id: str, checkpoint_ns: str) -> None:
        """Prune the thread its schedule says is due (PruningPutMixin).

        Args:
            thread_id: The thread (the run id) whose checkpoint was just stored.
            checkpoint_ns: Unused: PostgresSaver prunes every namespace of the thread.
        """
        try:
            self.prune([thread_id], strategy="keep_latest")
        except psycopg.Error:
            # A concurrent prune of the same thread (a serialization failure): storage
            # hygiene, retried at the next schedule; never a failed run.
            log.warning("could not prune the checkpoints of run %s", thread_id, exc_info=True)


def open_postgres_saver(
    sqlalchemy_url: str, *, max_connections: int
) -> tuple[PrunedPostgresSaver, Callable[[], None]]:
    """A PostgresSaver on its own pool, its tables set up; returns it with its closer.

    The connection options are the ones PostgresSaver requires (autocommit, dict rows, no
    server-side prepared statements). The pool checks a connection before lending it, so
    a restarted database costs one failed check, not a failed run.
    """
    conninfo = libpq_url(sqlalchemy_url)
    pool: ConnectionPool[psycopg.Connection[dict[str, object]]] = ConnectionPool(
        conninfo,
        min_size=1,
        max_size=max(2, max_connections),
        kwargs={"autocommit": True, "prepare_threshold": 0, "row_factory": dict_row},
        check=ConnectionPool.check_connection,
        name="ltaa-checkpoints",
        open=True,
    )
    saver = PrunedPostgresSaver(pool, prune_every=PRUNE_EVERY)
    try:
        with psycopg.connect(conninfo, autocommit=True) as lock_conn:
            lock_conn.execute("SELECT pg_advisory_lock(%s)", (SETUP_LOCK_KEY,))
            saver.setup()
    except BaseException:
        pool.close()
        raise
    return saver, pool.close
