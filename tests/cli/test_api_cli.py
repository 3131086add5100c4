"""`ltaa allocate` and `ltaa serve` through typer's CliRunner."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from app.cli import cli
from app.config import Settings
from app.main import create_app
from tests.fakes.fake_messages_api import FakeMessagesAPI


@pytest.fixture
def runner(tmp_path: Path) -> CliRunner:
    return CliRunner(env={"LTAA_DATA_DIR": str(tmp_path / "cli-data"), "COLUMNS": "120"})


def without_timing(body: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in body.items() if k != "elapsed_ms"}


@pytest.mark.parametrize(
    ("args", "request_body"),
    [
        (
            ["--solver", "dp", "--scenario", "baseline", "--mode", "balanced"],
            {"solver": "dp", "scenario": "baseline", "mode": "balanced"},
        ),
        (
            [
                "--solver",
                "optimal",
                "--scenario",
                "light_excels",
                "--mode",
                "aggressive_balance",
                "--max-deviation",
                "2",
                "--seed",
                "5",
            ],
            {
                "solver": "optimal",
                "scenario": "light_excels",
                "mode": "aggressive_balance",
                "max_deviation": 2,
                "seed": 5,
            },
        ),
    ],
)
def test_allocate_json_equals_the_api_response(
    runner: CliRunner, client: TestClient, args: list[str], request_body: dict[str, Any]
) -> None:
    result = runner.invoke(cli, ["allocate", *args, "--json"])
    assert result.exit_code == 0, result.output
    api = client.post("/allocate", json=request_body)
    assert api.status_code == 200
    assert without_timing(json.loads(result.stdout)) == without_timing(api.json())


def test_allocate_prints_assignments_and_metrics_tables(runner: CliRunner) -> None:
    result = runner.invoke(
        cli,
        [
            "allocate",
            "--solver",
            "dp",
            "--scenario",
            "baseline",
            "--mode",
            "balanced",
            "--show-tasks",
        ],
    )
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "Expected success" in out and "0.786111" in out
    assert "Balance score" in out and "Simulated completion" in out
    assert "Assignments by robot" in out and "light" in out and "Navigation" in out


def test_allocate_with_an_instance_file_and_options(runner: CliRunner, tmp_path: Path) -> None:
    path = tmp_path / "instance.json"
    path.write_text(
        json.dumps(
            {
                "tasks": [
                    {"action_id": 1, "action_name": "Lift", "features": ["heavy"]},
                    {"id": "b", "features": ["heavy"]},
                ],
                "robots": [
                    {"name": "x", "success": {"heavy": 0.9}},
                    {"name": "y", "success": {"heavy": 0.4}},
                ],
            }
        )
    )
    result = runner.invoke(
        cli,
        [
            "allocate",
            "--solver",
            "brute_force",
            "--instance",
            str(path),
            "--mode",
            "success_focused",
            "--json",
        ],
    )
    assert result.exit_code == 0, result.output
    body = json.loads(result.stdout)
    assert [a["robot"] for a in body["assignments"]] == ["x", "x"]

    bad = runner.invoke(cli, ["allocate", "--solver", "dp", "-o", "bogus=1", "--json"])
    assert bad.exit_code == 1
    assert json.loads(bad.stdout)["detail"][0]["loc"] == ["body", "options", "bogus"]


def test_allocate_errors_match_the_api_errors(runner: CliRunner, client: TestClient) -> None:
    result = runner.invoke(cli, ["allocate", "--solver", "dp", "--scenario", "mars", "--json"])
    assert result.exit_code == 1
    api = client.post("/allocate", json={"solver": "dp", "scenario": "mars"})
    assert json.loads(result.stdout) == api.json()

    plain = runner.invoke(cli, ["allocate", "--solver", "dp", "--max-deviation", "-1"])
    assert plain.exit_code == 1
    assert "max_deviation" in plain.stderr


def test_serve_migrates_then_runs_the_factory(
    runner: CliRunner, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import uvicorn

    from app.cli import serve as serve_command

    migrated: list[str] = []
    served: dict[str, Any] = {}
    monkeypatch.setattr(
        serve_command, "apply_migrations", lambda settings: migrated.append(settings.db_url)
    )
    monkeypatch.setattr(uvicorn, "run", lambda app, **kw: served.update(app=app, **kw))
    result = runner.invoke(cli, ["serve", "--port", "8123"])
    assert result.exit_code == 0, result.output
    assert migrated == [f"sqlite:///{tmp_path.as_posix()}/cli-data/ltaa.db"]
    assert served == {
        "app": "app.asgi:create_app",
        "factory": True,
        "host": "127.0.0.1",
        "port": 8123,
    }


def test_apply_migrations_creates_the_database(tmp_path: Path) -> None:
    from app.cli import apply_migrations
    from app.config import Settings

    settings = Settings(data_dir=tmp_path / "fresh")
    apply_migrations(settings)
    assert (tmp_path / "fresh" / "ltaa.db").is_file()


def test_run_completes_with_a_summary(runner: CliRunner) -> None:
    result = runner.invoke(cli, ["run", "--scenario", "baseline", "--mode", "balanced"])
    assert result.exit_code == 0, result.output
    assert "completed" in result.output and "36 of 36" in result.output


def test_run_refuses_a_data_directory_a_server_is_using(runner: CliRunner, tmp_path: Path) -> None:
    settings = Settings(data_dir=tmp_path / "cli-data", anthropic_api_key=None)
    with TestClient(create_app(settings)):
        result = runner.invoke(cli, ["run"])
    assert result.exit_code == 1
    assert "another LTAA process" in result.output
    assert "Traceback" not in result.output


def test_run_applies_the_token_budget_setting(runner: CliRunner) -> None:
    with FakeMessagesAPI() as api:
        result = runner.invoke(
            cli,
            ["run", "--reasoner", "anthropic"],
            env={
                "ANTHROPIC_API_KEY": "test-key",
                "LTAA_ANTHROPIC_BASE_URL": api.base_url,
                "LTAA_RUN_TOKEN_BUDGET": "1",
            },
        )
        answered = api.answered()
    assert result.exit_code == 0, result.output
    # The first call spends the budget; every later task goes to the rules reasoner.
    assert answered == 1
    assert "LLM calls / tokens in / out" in result.output


def test_run_with_a_contested_scope_asks_the_model_for_contested_decisions_only(
    runner: CliRunner,
) -> None:
    from tests.fakes.llm_providers import PROVIDERS

    openai = PROVIDERS["openai"]
    with openai.fake() as api:
        result = runner.invoke(
            cli, ["run", "--reasoner", "openai", "--llm-scope", "contested"], env=openai.env(api)
        )
        answered = api.answered()
    assert result.exit_code == 0, result.output
    assert 0 < answered <= 0.4 * 36  # baseline / balanced: about a fifth
