"""Fixtures for the unit tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest


@pytest.fixture(scope="session")
def mpxj() -> Iterator[None]:
    """MPXJ in a JVM, started once per test process (JPype cannot start a second one)."""
    from tests.mpxj_oracle import start_jvm

    start_jvm()
    yield
