"""Settings come from LTAA_* environment variables, with paths derived from data_dir."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from app.config import Settings, SettingsError, get_settings
from tests.support.server import BIN


def test_defaults_derive_paths_from_data_dir(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("LTAA_DATA_DIR", raising=False)
    s = Settings()
    assert s.data_dir == Path("data")
    assert s.database_url == "sqlite:///data/ltaa.db"
    assert s.checkpoint_path == Path("data/checkpoints.sqlite")
    assert (s.host, s.port, s.max_concurrent_runs, s.auto_resume) == ("127.0.0.1", 8000, 4, True)
    assert s.default_reasoner == "rules"


def test_environment_with_prefix(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("LTAA_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("LTAA_MAX_CONCURRENT_RUNS", "7")
    monkeypatch.setenv("LTAA_AUTO_RESUME", "false")
    monkeypatch.setenv("LTAA_TEST_PAUSE", "18:reason:before")
    monkeypatch.setenv("LTAA_DATABASE_URL", "postgresql://db/ltaa")
    s = get_settings()
    assert s.max_concurrent_runs == 7 and s.auto_resume is False
    assert s.test_pause == "18:reason:before"
    assert s.database_url == "postgresql://db/ltaa"
    assert s.checkpoint_path == tmp_path / "checkpoints.sqlite"


@pytest.mark.parametrize("var", ["ANTHROPIC_API_KEY", "LTAA_ANTHROPIC_API_KEY"])
def test_api_key_from_either_variable_and_never_printed(
    monkeypatch: pytest.MonkeyPatch, var: str
) -> None:
    monkeypatch.delenv("ANTHROPIC_API_KEY", raising=False)
    monkeypatch.delenv("LTAA_ANTHROPIC_API_KEY", raising=False)
    monkeypatch.setenv(var, "sk-test-123")
    s = get_settings()
    assert s.anthropic_api_key is not None
    assert s.anthropic_api_key.get_secret_value() == "sk-test-123"
    assert "sk-test-123" not in repr(s)


def test_invalid_environment_is_rejected(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LTAA_MAX_CONCURRENT_RUNS", "0")
    with pytest.raises(ValueError, match="LTAA_MAX_CONCURRENT_RUNS=0 is refused"):
        get_settings()


LLM_REFUSALS = {
    "LTAA_LLM_MAX_TOKENS=10": "each output-token cap must be 32-8192",
    "LTAA_LLM_MAX_TOKENS=400,400,500,500,600": "one per tier 0-3, not 5",
    "LTAA_LLM_MAX_TOKENS=many": "=many is refused: Input should be a valid integer",
    "LTAA_LLM_GIVE_UP_AFTER=-1": "greater than or equal to 0",
    "LTAA_LLM_REPLY_FORMAT=xml": "'json_schema', 'json_object' or 'markdown'",
}


@pytest.mark.parametrize("setting,why", LLM_REFUSALS.items(), ids=LLM_REFUSALS.keys())
def test_an_llm_setting_out_of_range_is_refused_naming_it(
    setting: str, why: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    name, value = setting.split("=", 1)
    monkeypatch.setenv(name, value)
    with pytest.raises(SettingsError) as refused:
        get_settings()
    assert str(refused.value).startswith("the service cannot start: ")
    assert name in str(refused.value) and why in str(refused.value)


def test_the_server_itself_stops_at_start_with_the_sentence(tmp_path: Path) -> None:
    """docs/reasoners.md#bounded-cost: the server, as `make run` starts it, refuses."""
    env = {**os.environ, "LTAA_DATA_DIR": str(tmp_path), "LTAA_LLM_GIVE_UP_AFTER": "-1"}
    started = subprocess.run(
        [str(BIN / "uvicorn"), "app.asgi:create_app", "--factory", "--port", "1"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert started.returncode != 0
    assert started.stderr.strip().splitlines()[-1] == (
        "app.config.SettingsError: the service cannot start: LTAA_LLM_GIVE_UP_AFTER=-1 is "
        "refused: Input should be greater than or equal to 0."
    )
