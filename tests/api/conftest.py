"""An in-process client against create_app() with a temporary data directory."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.config import Settings
from app.main import create_app

ClientFactory = Callable[..., TestClient]


@pytest.fixture
def make_client(settings: Settings) -> Iterator[ClientFactory]:
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
        client = TestClient(create_app(settings.model_copy(update=overrides)))
        opened.append(client.__enter__())
        return client

    yield factory
    for client in opened:
        client.__exit__(None, None, None)


@pytest.fixture
def client(make_client: ClientFactory) -> TestClient:
    return make_client()
