"""Hostile input from schemathesis: requests generated from the app's own OpenAPI schema,
valid and invalid, sent in-process to the ASGI app, with every check on (`--checks all`),
with API keys configured and without. No request may end in a 5xx, every response must
conform to the schema (a documented status code, content type, headers and a body matching
its model), schema-valid requests are accepted and schema-invalid ones refused. The rules
no JSON Schema can state, and the 422 they answer, are listed with their reasons in
tests/api/schemathesis.toml.

Every endpoint is covered with a bounded number of examples (a fixed seed via derandomize),
so the whole module stays well under a minute and a half.
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import schemathesis
from fastapi import FastAPI
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, settings
from pydantic import SecretStr
from schemathesis.python.asgi import shutdown_lifespans
from starlette.types import Receive, Scope, Send

from app.config import Settings
from app.main import create_app
from tests.support.polling import wait_until

CONFIG = schemathesis.Config.from_path(Path(__file__).with_name("schemathesis.toml"))

SUPERVISOR_KEY = "schemathesis-supervisor-key-0123"
KEYS = SecretStr(f"{SUPERVISOR_KEY}:supervisor")
AUTH = {"Authorization": f"Bearer {SUPERVISOR_KEY}"}


class AppUnderTest:
    """The ASGI app schemathesis calls: it forwards to the app the running test built.

    The schema is loaded at import (schemathesis makes one test per operation at
    collection), but each test needs its own app over its own temporary data directory.
    """

    def __init__(self) -> None:
        self.app: FastAPI | None = None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        assert self.app is not None, "no app: the test did not request the app_under_test fixture"
        await self.app(scope, receive, send)


APP = AppUnderTest()
# schemathesis's own negative-data strategies use `random` (a deprecation in hypothesis);
# nothing this project can change.
pytestmark = pytest.mark.filterwarnings("ignore::hypothesis.errors.HypothesisDeprecationWarning")


def _openapi_document(keys: SecretStr | None) -> dict[str, Any]:
    # Building the app opens nothing (the lifespan does); the schema needs no data directory.
    return create_app(Settings(api_keys=keys, host="127.0.0.1")).openapi()


schema = schemathesis.openapi.from_dict(_openapi_document(KEYS), config=CONFIG)
schema.app = APP
# With no keys the document declares no security: a request without a key is valid there.
open_schema = schemathesis.openapi.from_dict(_openapi_document(None), config=CONFIG)
open_schema.app = APP

# Requests generated from the schema are sent both as they are and to the run the fixture
# stored, so GET /runs/{id}, its trace and events are answered with bodies too, not only 404s.
RUN_PATHS = r"\{run_id\}"
# The run tests take only those paths. Written as an exclusion: with the [[operations]]
# sections of schemathesis.toml in the config, schemathesis 4 adds an include filter of
# its own that matches every operation, and include filters are OR-ed, so
# `include(path_regex=RUN_PATHS)` selected all of them (the other 21 operations ran a
# second time under this test, 29 of its 54 CPU-s). Exclusions apply first, whatever else.
NOT_RUN_PATHS = r"^(?!.*\{run_id\})"
# POST /admin/backup writes a copy of the store (inside LTAA_BACKUP_DIR): generated paths
# would be refused or litter the test's directory. tests/operations/test_backup.py covers it.
WRITES_FILES = r"^/admin/backup$"
HYPOTHESIS = settings(
    max_examples=40,
    deadline=None,  # in-process calls share 2 cores with other tests; time is bounded by count
    derandomize=True,
    database=None,
    suppress_health_check=[
        HealthCheck.too_slow,
        HealthCheck.filter_too_much,
        HealthCheck.data_too_large,
        HealthCheck.function_scoped_fixture,
    ],
)


@pytest.fixture
def keys() -> SecretStr | None:
    return KEYS


@pytest.fixture
def app_settings(settings: Settings, keys: SecretStr | None) -> Settings:
    # One run at a time and short event streams: POST /runs starts background runs, and a
    # stream stays open while its run is running.
    return settings.model_copy(
        update={
            "api_keys": keys,
            "max_concurrent_runs": 1,
            "events_max_stream_s": 0.5,
            "events_poll_s": 0.05,
        }
    )


@pytest.fixture
def app_under_test(app_settings: Settings, migrated_store: Path) -> Iterator[FastAPI]:
    store = app_settings.data_dir / "ltaa.db"
    # Not the completed store of `stored_run` (which the run tests request before this).
    if app_settings.db_url == f"sqlite:///{store.as_posix()}" and not store.exists():
        # The app's lifespan finds the store at head and migrates nothing
        # (tests/support/clients.py: migrated_store).
        store.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(migrated_store, store)
    APP.app = create_app(app_settings)
    try:
        yield APP.app
    finally:
        # Drains the run worker (background runs stop at a node boundary) before the
        # temporary data directory goes away. schemathesis's own teardown does the same.
        shutdown_lifespans()
        APP.app = None


@pytest.fixture(scope="module")
def completed_store(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A data directory holding one completed baseline run, made once per module (in each
    pytest-xdist worker that runs these tests) and never opened again: tests get copies."""
    data = tmp_path_factory.mktemp("completed-store") / "data"
    made = Settings(
        data_dir=data,
        api_keys=KEYS,
        anthropic_api_key=None,
        anthropic_base_url=None,
        openai_base_url=None,
        openai_api_key=None,
        openai_model=None,
        max_concurrent_runs=1,
    )
    with TestClient(create_app(made)) as client:
        body = {"scenario": "baseline", "reasoner": "rules"}
        run_id = str(client.post("/runs", json=body, headers=AUTH).json()["id"])
        wait_until(client, run_id, ("completed",), timeout=30, headers=AUTH)
    return data, run_id


@pytest.fixture
def stored_run(app_settings: Settings, completed_store: tuple[Path, str]) -> str:
    """A completed run in the data directory the app under test will open: a copy of the
    module's completed store (the requests may change it), the same store each test made
    for itself before, without running the same 36 tasks again for every operation."""
    data, run_id = completed_store
    shutil.copytree(data, app_settings.data_dir, ignore=shutil.ignore_patterns("*.lock"))
    return run_id


@schema.exclude(path_regex=RUN_PATHS).exclude(path_regex=WRITES_FILES).parametrize()
@HYPOTHESIS
def test_api_conforms_to_its_schema(case: schemathesis.Case, app_under_test: FastAPI) -> None:
    case.call_and_validate(headers=AUTH)


@open_schema.exclude(path_regex=RUN_PATHS).exclude(path_regex=WRITES_FILES).parametrize()
@pytest.mark.parametrize("keys", [None])
@HYPOTHESIS
def test_api_without_keys_conforms_to_its_schema(
    case: schemathesis.Case, app_under_test: FastAPI
) -> None:
    case.call_and_validate()


@schema.exclude(path_regex=NOT_RUN_PATHS).exclude(path_regex=WRITES_FILES).parametrize()
@HYPOTHESIS
def test_run_endpoints_conform_to_their_schema(
    case: schemathesis.Case, stored_run: str, app_under_test: FastAPI
) -> None:
    case.call_and_validate(headers=AUTH)
    case.path_parameters = {**(case.path_parameters or {}), "run_id": stored_run}
    # The id is now a real one, whatever was generated; a negative case may have been
    # negative only in the id, so that the app now rightly accepts it.
    case.call_and_validate(
        headers=AUTH, excluded_checks=[schemathesis.checks.negative_data_rejection]
    )


def test_the_run_tests_and_the_others_split_the_operations_between_them() -> None:
    def labels(selected: Any) -> set[str]:
        return {result.ok().label for result in selected.get_all_operations()}

    run_tests = labels(schema.exclude(path_regex=NOT_RUN_PATHS).exclude(path_regex=WRITES_FILES))
    others = labels(schema.exclude(path_regex=RUN_PATHS).exclude(path_regex=WRITES_FILES))
    every = labels(schema.exclude(path_regex=WRITES_FILES))
    assert run_tests and all("{run_id}" in label for label in run_tests)
    assert run_tests.isdisjoint(others) and run_tests | others == every
