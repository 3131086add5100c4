"""Fixtures shared by every test directory."""

from __future__ import annotations

import gc
from collections.abc import Generator, Iterator
from pathlib import Path

import pytest

from app.config import Settings
from tests.fakes.llm_providers import PROVIDERS, Provider

# The directories whose tests take minutes (servers killed and restarted, a browser), in
# the order they are handed out: see pytest_collection_modifyitems.
LONG_FIRST = ("tests/e2e/", "tests/browser/")


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
    """The long tests first, longest-first scheduling: pytest-xdist's `load` with
    --maxschedchunk=1 (pyproject.toml) hands tests out from the head of this list one at a
    time as workers finish, so the end-to-end and browser tests (and the tests marked slow)
    spread over every worker at the start and the short ones fill in after them; in
    collection order one of those minutes-long tests could start last and the whole run
    would wait for it."""

    def rank(item: pytest.Item) -> int:
        if item.get_closest_marker("slow"):  # training runs of a minute, wherever they live
            return 0
        return next(
            (i for i, prefix in enumerate(LONG_FIRST) if item.nodeid.startswith(prefix)),
            len(LONG_FIRST),
        )

    items.sort(key=rank)  # stable: within a rank, collection order


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
    """MPXJ in a JVM (tests/mpxj_oracle.py), started once per test process: JPype cannot
    start a second JVM in a process."""
    from tests.mpxj_oracle import start_jvm

    start_jvm()
    yield
