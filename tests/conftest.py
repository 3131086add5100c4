"""Fixtures shared by every test directory, and the order the suite runs in.

The tests mirror app/ (tests/<feature>/ beside app/<feature>/, checked by
tests/project/test_tests_mirror_app.py); what several features' tests share is defined once,
in tests/support/ (clients and stores: tests/support/clients.py, registered below; the
browser's: tests/support/browser.py, taken in by tests/console/conftest.py)."""

from __future__ import annotations

import gc
from collections.abc import Generator, Iterator
from functools import cache
from pathlib import Path

import pytest
from xdist.remote import Producer
from xdist.scheduler import LoadScopeScheduling

from app.config import Settings
from tests.fakes.llm_providers import PROVIDERS, Provider

pytest_plugins = ("tests.support.clients", "tests.support.mqtt_broker")

ROOT = Path(__file__).resolve().parents[1]


@pytest.hookimpl(wrapper=True)
def pytest_collection(session: pytest.Session) -> Generator[None, object, object]:
    """Collect with the cyclic garbage collector paused, then freeze what collection made.

    Collecting imports the app, schemathesis (which builds its coverage cases for every
    operation as it collects), hypothesis, torch, playwright, ...: hundreds of thousands of
    long-lived objects that every full collection walked again while they were being made,
    freeing nothing. Measured on the whole suite, one process: 14.6 CPU-s collecting with
    the collector on, 8.6 with it paused; each of the four xdist workers collects the whole
    suite. `gc.freeze` keeps the tests' own collections from walking those objects again;
    what the tests create is collected as usual."""
    gc.disable()
    try:
        return (yield)
    finally:
        gc.enable()
        gc.freeze()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The long tests first, longest-first scheduling: the queue below
    (pytest_xdist_make_scheduler) hands tests out from the head of this list as workers
    finish, so the end-to-end and browser tests (and the tests marked slow) spread over
    every worker at the start and the short ones fill in after them; in collection order
    one of those minutes-long tests could start last and the whole run would wait for it."""

    def rank(item: pytest.Item) -> int:
        if item.get_closest_marker("model"):  # the real language model: the longest of all
            return -1
        if item.get_closest_marker("slow"):  # training runs of a minute, wherever they live
            return 0
        # Minutes-long: servers killed and restarted (e2e), then a browser's (browser).
        if item.get_closest_marker("e2e"):
            return 1 if _is_browser(item.nodeid.split("::", 1)[0]) else 0
        return 2

    items.sort(key=rank)  # stable: within a rank, collection order


class ModulesSharingAServer(LoadScopeScheduling):
    """pytest-xdist's queue (its `loadscope` scheduler, in the order collected): each
    worker holds up to three tests and takes the next unit from the head as it finishes
    one. A unit is one test, or a whole end-to-end or browser module whose tests share a
    module-scoped fixture (a server, often with runs or a PostgreSQL database behind it):
    handed out one test at a time, such a module's tests landed on every worker and each
    worker started the module's server again (3 CPU-s or more a time). pytest-xdist's own
    `loadgroup` cannot do this with pytest 9 (it renames `item._nodeid`, which pytest 9
    no longer reads)."""

    def _split_scope(self, nodeid: str) -> str:
        module = nodeid.split("::", 1)[0]
        return module if _shares_a_server(module) else nodeid


@cache
def _shares_a_server(module: str) -> bool:
    """Every browser module (the `server` of tests/support/browser.py is module-scoped), and
    the end-to-end modules that define a module-scoped fixture."""
    if _is_browser(module):
        return True
    path = ROOT / module
    if not path.is_file():
        return False
    text = path.read_text()
    return "pytest.mark.e2e" in text and 'scope="module"' in text


def _is_browser(module: str) -> bool:
    """Browser modules are named test_*_browser.py (tests/console/)."""
    return module.endswith("_browser.py")


def pytest_xdist_make_scheduler(config: pytest.Config, log: Producer) -> ModulesSharingAServer:
    """The scheduler `make test` runs the suite with (docs/development.md#tests-and-ci-time):
    the collection order kept (no reordering by unit size)."""
    config.option.loadscopereorder = False
    return ModulesSharingAServer(config, log)


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    """Settings isolated from the developer's environment: a fresh data_dir, no API key and
    no LLM server."""
    return Settings(
        data_dir=tmp_path / "data",
        anthropic_api_key=None,
        anthropic_base_url=None,
        openai_base_url=None,
        openai_api_key=None,
        openai_model=None,
    )


@pytest.fixture(params=list(PROVIDERS.values()), ids=list(PROVIDERS))
def provider(request: pytest.FixtureRequest) -> Provider:
    """Each LLM provider in turn (anthropic, openai): a test taking it runs once for each."""
    provider: Provider = request.param
    return provider


@pytest.fixture(scope="session")
def mpxj() -> Iterator[None]:
    """MPXJ in a JVM (tests/support/mpxj_oracle.py), started once per test process: JPype cannot
    start a second JVM in a process."""
    from tests.support.mpxj_oracle import start_jvm

    start_jvm()
    yield
