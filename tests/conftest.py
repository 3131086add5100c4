"""Fixtures shared by every test directory."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.config import Settings
from tests.fakes.llm_providers import PROVIDERS, Provider


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
