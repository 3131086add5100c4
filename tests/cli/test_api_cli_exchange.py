"""`ltaa import FILE` and `ltaa schedule --format mspdi` through typer's CliRunner: the
draft printed is the one POST /schedules/import answers, refusals name the field and exit
1, and the plan's MSPDI imports back to the plan's tasks (docs/exchange.md). `--site`
reads a real server's estimates: tests/exchange/test_exchange_e2e.py."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from app.cli import cli
from app.exchange import read_mspdi, read_xer
from tests.allocation.test_api_timed import timed
from tests.support.exchange_files import small_mspdi
from tests.support.exchange_support import files


@pytest.fixture
def runner(tmp_path: Path) -> CliRunner:
    return CliRunner(env={"LTAA_DATA_DIR": str(tmp_path / "cli-data"), "COLUMNS": "140"})


@pytest.fixture
def plan_file(tmp_path: Path) -> Path:
    path = tmp_path / "fit-out.xml"
    path.write_bytes(small_mspdi(typed=True))
    return path


def test_import_prints_the_draft_the_endpoint_answers(
    runner: CliRunner, client: TestClient, plan_file: Path
) -> None:
    result = runner.invoke(cli, ["import", str(plan_file), "--default-features", "sweep"])
    assert result.exit_code == 0, result.output
    answer = client.post(
        "/schedules/import", content=plan_file.read_bytes(), params={"default_features": "sweep"}
    )
    assert json.loads(result.stdout) == answer.json()
    draft = json.loads(result.stdout)
    assert draft["tasks"][1]["after"] == [{"task": "1", "type": "SS", "lag": 20}]
    assert draft["source"]["format"] == "mspdi" and draft["skipped"] == []
    named = runner.invoke(cli, ["import", str(plan_file), "--format", "mspdi",
                                "--features-field", "Text1"])  # fmt: skip
    assert named.exit_code == 0, named.output
    assert json.loads(named.stdout)["tasks"] == draft["tasks"]


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--format", "xer"], "file: expected an XER file (Primavera P6)"),
        (["--features-field", "Text9"], "features_field: "),
    ],
)
def test_import_refusals_name_the_field(
    runner: CliRunner, plan_file: Path, args: list[str], words: str
) -> None:
    result = runner.invoke(cli, ["import", str(plan_file), *args])
    assert result.exit_code == 1
    assert words in result.output, result.output
    assert result.stdout == ""  # nothing half printed


def test_import_refuses_a_missing_file_and_a_json_one(runner: CliRunner, tmp_path: Path) -> None:
    missing = runner.invoke(cli, ["import", str(tmp_path / "none.xml")])
    assert missing.exit_code == 1 and "cannot read" in missing.output
    wrong = tmp_path / "plan.json"
    wrong.write_text(json.dumps(timed()))
    refused = runner.invoke(cli, ["import", str(wrong)])
    assert refused.exit_code == 1 and "expected an MSPDI file" in refused.output


def test_import_refuses_a_file_over_the_import_limit(runner: CliRunner, plan_file: Path) -> None:
    result = runner.invoke(cli, ["import", str(plan_file)], env={"LTAA_IMPORT_MAX_BYTES": "100"})
    assert result.exit_code == 1 and "LTAA_IMPORT_MAX_BYTES" in result.output


def test_schedule_as_mspdi_imports_back_to_the_plans_tasks(
    runner: CliRunner, tmp_path: Path
) -> None:
    body = timed()
    path = tmp_path / "site.json"
    path.write_text(json.dumps(body))
    result = runner.invoke(cli, ["schedule", str(path), "--method", "greedy", "--format", "mspdi"])
    assert result.exit_code == 0, result.output
    assert result.stdout.startswith("<?xml")
    draft = read_mspdi(result.stdout_bytes, features_field="Text1")
    assert [t["id"] for t in draft.tasks] == [str(t["id"]) for t in body["tasks"]]
    sent = {str(t["id"]): t for t in body["tasks"]}
    for task in draft.tasks:
        assert task["features"] == sent[task["id"]]["features"]
        assert [a["task"] for a in task["after"]] == [
            str(p) for p in sent[task["id"]].get("after", [])
        ]
    assert draft.start is not None and draft.start.startswith(body["start"][:16])


def test_the_readmes_example_file_is_the_test_file(runner: CliRunner) -> None:
    """docs/examples/level-3-fit-out.xml (README's tour, step 9) imports as the file these
    tests write: regenerate it from tests.support.exchange_files.small_mspdi if the writer
    changes."""
    example = Path(__file__).resolve().parents[2] / "docs/examples/level-3-fit-out.xml"
    result = runner.invoke(cli, ["import", str(example)])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout) == read_mspdi(small_mspdi()).to_dict()


@pytest.mark.usefixtures("mpxj")
def test_import_reads_an_xer_file_mpxj_wrote(runner: CliRunner, tmp_path: Path) -> None:
    path = tmp_path / "slab.xer"
    path.write_bytes(files()["xer"])
    for args in ([], ["--format", "xer"]):
        result = runner.invoke(cli, ["import", str(path), *args])
        assert result.exit_code == 0, result.output
        assert json.loads(result.stdout) == read_xer(files()["xer"]).to_dict()
