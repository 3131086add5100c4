"""The run worker for the configured database: leases on PostgreSQL, one process on SQLite.

The worker is composed, not subclassed: an ownership strategy (app.runs.ownership) and a
checkpointer, chosen here from the database URL.
"""

from __future__ import annotations

import logging
from pathlib import Path

from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.graph.builder import NODES, TASK_START
from app.graph.checkpoint import open_sqlite_saver
from app.graph.pause import NodeHook, PausePoint, pause_hook
from app.runs.ownership import LocalOwnership, Ownership
from app.runs.worker import Checkpointer, RunWorker

log = logging.getLogger("ltaa.runs")


def uses_leases(database_url: str) -> bool:
    """SQLite is the single-process embedded store (its checkpointer is a local file), so
    runs are recovered at start-up; PostgreSQL may be shared by several processes."""
    return make_url(database_url).get_backend_name() == "postgresql"


def sqlite_checkpointer(settings: Settings) -> Checkpointer:
    path = Path(settings.checkpoint_file)
    path.parent.mkdir(parents=True, exist_ok=True)
    # One connection for the process (SqliteSaver serialises on its own lock), a generous
    # busy timeout instead of "database is locked" under load, integer channel versions
    # (half the bytes per checkpoint) and synchronous=NORMAL: in WAL mode a kill -9 loses
    # nothing committed; only an OS crash could lose the last steps. Checkpoints are
    # written where a task begins (and where the graph pauses or ends), not at each of its
    # 7+ super-steps: a resume decides the killed task again from its start, every node's
    # side effects being idempotent and every LLM reply recorded (app.graph.checkpoint._sparse).
    saver = open_sqlite_saver(path, compact=True, synchronous="NORMAL", boundary=(TASK_START,))
    return saver, saver.conn.close


def postgres_checkpointer(settings: Settings) -> Checkpointer:
    from app.graph.checkpoint.postgres import open_postgres_saver

    return open_postgres_saver(settings.db_url, max_connections=settings.max_concurrent_runs)


def pause_hook_from_settings(settings: Settings) -> NodeHook | None:
    """The test-only pause point of `LTAA_TEST_PAUSE`, announced loudly: a server holding
    runs on purpose must never pass for a healthy one."""
    if settings.test_pause is None:
        return None
    point = PausePoint.from_setting(settings.test_pause)
    log.warning(
        "LTAA_TEST_PAUSE is set: every run will hold at task %d %s %s (a test seam; "
        "never set it in production)",
        point.task_index,
        "after" if point.after else "before",
        point.node,
    )
    return pause_hook(point, frozenset(NODES))


def make_worker(
    *,
    settings: Settings,
    sessions: sessionmaker[Session],
    node_hook: NodeHook | None = None,
    serving: str | None = None,
) -> RunWorker:
    """`node_hook`: in-process tests pass a hook directly; otherwise LTAA_TEST_PAUSE's.
    `serving`: the URL the server answers on, recorded with the embedded store's lock."""
    if settings.test_graph_version is not None:
        log.warning(
            "LTAA_TEST_GRAPH_VERSION is set: this process claims graph version %s instead of "
            "its own (a test seam; never set it in production)",
            settings.test_graph_version,
        )
    ownership: Ownership
    if uses_leases(settings.db_url):
        from app.runs.ownership import LeaseOwnership

        ownership = LeaseOwnership(settings=settings, sessions=sessions)
        open_checkpointer = postgres_checkpointer
    else:
        # Claims the store first: a second process must fail before it opens anything.
        ownership = LocalOwnership(settings=settings, sessions=sessions, serving=serving)
        open_checkpointer = sqlite_checkpointer
    try:
        checkpointer = open_checkpointer(settings)
    except BaseException:
        ownership.close()
        raise
    return RunWorker(
        settings=settings,
        sessions=sessions,
        ownership=ownership,
        checkpointer=checkpointer,
        node_hook=node_hook if node_hook is not None else pause_hook_from_settings(settings),
    )
