"""`ltaa schedule` through typer's CliRunner: the timeline, JSON equal to /allocate's
schedule block, CSV and iCalendar read back with independent parsers, errors as the API's."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import icalendar
import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from app.cli import cli
from app.domain.catalog import timed_scenario
from tests.allocation.test_api_timed import timed
from tests.support.timed_checks import feasibility_errors


@pytest.fixture
def runner(tmp_path: Path) -> CliRunner:
    return CliRunner(env={"LTAA_DATA_DIR": str(tmp_path / "cli-data"), "COLUMNS": "140"})


@pytest.fixture
def site_file(tmp_path: Path) -> Path:
    path = tmp_path / "site.json"
    path.write_text(json.dumps(timed()))  # its solver and other keys are ignored
    return path


def test_the_timed_scenario_prints_each_robots_timeline(runner: CliRunner) -> None:
    result = runner.invoke(cli, ["schedule", "--time-limit", "2", "--method", "schedule"])
    assert result.exit_code == 0, result.output
    for robot in timed_scenario("baseline_timed").instance.robots:
        assert f"({robot.name})" in result.output
    assert "makespan" in result.output and "bound" in result.output
    assert "Beep" in result.output and "travel to" in result.output


def test_a_small_site_is_proven_optimal_on_the_timeline(runner: CliRunner, site_file: Path) -> None:
    result = runner.invoke(cli, ["schedule", str(site_file), "--mode", "success_focused"])
    assert result.exit_code == 0, result.output
    assert "optimal (bound 72, gap 0.0%)" in result.output
    assert "makespan 72 min" in result.output


def test_json_is_the_schedule_block_of_allocate(
    runner: CliRunner, client: TestClient, site_file: Path
) -> None:
    result = runner.invoke(
        cli, ["schedule", str(site_file), "--method", "greedy", "--format", "json"]
    )
    assert result.exit_code == 0, result.output
    answer = client.post("/allocate", json=timed("greedy")).json()
    assert json.loads(result.stdout) == answer["schedule"]
    assert feasibility_errors(timed(), json.loads(result.stdout)) == []


def test_csv_has_one_row_per_task(runner: CliRunner, site_file: Path) -> None:
    result = runner.invoke(cli, ["schedule", str(site_file), "--format", "csv"])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(io.StringIO(result.stdout, newline="")))
    assert [row["task_id"] for row in rows] == [str(t["id"]) for t in timed()["tasks"]]
    assert all(row["start_at"].endswith("+01:00") for row in rows)


def test_ics_has_one_event_per_task(runner: CliRunner) -> None:
    result = runner.invoke(
        cli, ["schedule", "--method", "optimal", "--format", "ics", "--mode", "success_focused"]
    )
    assert result.exit_code == 0, result.output
    calendar = icalendar.Calendar.from_ical(result.stdout_bytes)
    events = calendar.walk("VEVENT")
    assert len(events) == timed_scenario("baseline_timed").instance.n_tasks
    assert {str(e["RESOURCES"]) for e in events} <= {"light", "medium", "heavy"}


@pytest.mark.parametrize(
    ("args", "where", "words"),
    [
        (["nowhere"], "source", "baseline_timed"),
        (["baseline"], "source", "neither a file"),
        (["--time-limit", "500"], "options.time_limit_s", "120"),
        (["--method", "simplex"], "solver", "simplex"),
    ],
)
def test_errors_name_the_field(runner: CliRunner, args: list[str], where: str, words: str) -> None:
    result = runner.invoke(cli, ["schedule", *args, "--format", "json"])
    assert result.exit_code == 1
    detail = json.loads(result.stdout)["detail"][0]
    assert ".".join(map(str, detail["loc"][1:])) == where and words in detail["msg"]


def test_an_instance_files_errors_are_the_apis(
    runner: CliRunner, client: TestClient, tmp_path: Path
) -> None:
    body: dict[str, Any] = timed()
    body["tasks"][0]["after"] = ["check"]  # a cycle
    path = tmp_path / "cycle.json"
    path.write_text(json.dumps(body))
    result = runner.invoke(cli, ["schedule", str(path), "--format", "json"])
    assert result.exit_code == 1
    assert json.loads(result.stdout) == client.post("/allocate", json=body).json()
    text = runner.invoke(cli, ["schedule", str(path)])
    assert text.exit_code == 1 and "tasks.2.after" in text.output and "cycle" in text.output


def test_an_untimed_instance_has_nothing_to_schedule(runner: CliRunner, tmp_path: Path) -> None:
    path = tmp_path / "untimed.json"
    path.write_text(
        json.dumps(
            {"tasks": [{"id": 1, "features": ["heavy"]}],
             "robots": [{"name": "a", "success": {"heavy": 0.9}}]}
        )
    )  # fmt: skip
    result = runner.invoke(cli, ["schedule", str(path)])
    assert result.exit_code == 1 and "untimed" in result.output


def test_names_in_messages_print_as_text(runner: CliRunner, tmp_path: Path) -> None:
    # A zone named like a rich closing tag, in an error and in a violation's message.
    body = timed()
    for task in body["tasks"]:
        task["zone"] = "[/z]" if task["zone"] == "C" else task["zone"]
    body["travel"] = {"A": {"B": 3}}  # nothing to or from "[/z]"
    path = tmp_path / "zones.json"
    path.write_text(json.dumps(body))
    result = runner.invoke(cli, ["schedule", str(path)])
    assert result.exit_code == 1 and "'[/z]'" in result.output, result.output
    tasks = [
        {"id": 1, "features": ["heavy"], "duration": 10, "zone": "[/z]"},
        {"id": 2, "features": ["heavy"], "duration": 10, "zone": "[/z]", "deadline": 15},
    ]
    robots = [{"name": "a", "success": {"heavy": 0.9}}, {"name": "b", "success": {"heavy": 0.5}}]
    path.write_text(json.dumps({"tasks": tasks, "robots": robots}))
    result = runner.invoke(
        cli, ["schedule", str(path), "--method", "greedy", "--mode", "success_focused"]
    )
    assert result.exit_code == 0, result.output
    assert "breaks deadline" in result.output and "[/z]" in result.output
