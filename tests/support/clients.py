"""An in-process client against create_app() with a temporary data directory."""

from __future__ import annotations

import shutil
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.config import Settings
from app.main import create_app
from app.store.migrate import upgrade_head
from tests.support.postgres import fresh_database

ClientFactory = Callable[..., TestClient]


@pytest.fixture(scope="session")
def migrated_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An empty SQLite store at head, migrated once per test process: about 0.1 s of CPU
    that each of some 700 clients would otherwise spend running the same migrations on a
    fresh file. The migrations themselves are tested where they are the subject
    (tests/store/test_migrations*.py, and every end-to-end server starts on a fresh store)."""
    path = tmp_path_factory.mktemp("migrated-store") / "ltaa.db"
    upgrade_head(f"sqlite:///{path.as_posix()}")
    return path


@pytest.fixture
def make_client(settings: Settings, migrated_store: Path) -> Iterator[ClientFactory]:
    """Build a client whose settings differ from the default test settings (e.g. a small body
    limit); the lifespan runs, and every client is closed at teardown."""
    opened: list[TestClient] = []

    def factory(**overrides: Any) -> TestClient:
        if opened and "data_dir" not in overrides:
            # Clients stay open until teardown, and one SQLite store serves one process at
            # a time (app.store.lock): each further client gets a store of its own.
            # (model_copy runs no validators: the paths derived from data_dir are reset too.)
            overrides |= {
                "data_dir": settings.data_dir.with_name(f"data-{len(opened) + 1}"),
                "database_url": None,
                "checkpoint_path": None,
            }
        built = settings.model_copy(update=overrides)
        store = built.data_dir / "ltaa.db"
        if built.db_url == f"sqlite:///{store.as_posix()}" and not store.exists():
            # The app's lifespan finds the store at head and migrates nothing.
            store.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(migrated_store, store)
        client = TestClient(create_app(built))
        opened.append(client.__enter__())
        return client

    yield factory
    for client in opened:
        client.__exit__(None, None, None)


@pytest.fixture
def client(make_client: ClientFactory) -> TestClient:
    return make_client()


@pytest.fixture(params=["sqlite", "postgresql"])
def any_db_client(
    request: pytest.FixtureRequest, make_client: ClientFactory
) -> Iterator[TestClient]:
    """A client on each store: a SQLite file, then a fresh PostgreSQL database migrated to
    head (SQLite hands times back without an offset, PostgreSQL with one)."""
    with ExitStack() as stack:
        if request.param == "sqlite":
            yield make_client()
            return
        url = stack.enter_context(fresh_database())
        upgrade_head(url)
        yield make_client(database_url=url)
