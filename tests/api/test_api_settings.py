"""Settings come from LTAA_* environment variables, with paths derived from data_dir."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.config import Settings, get_settings


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
    with pytest.raises(ValueError, match="max_concurrent_runs"):
        get_settings()
