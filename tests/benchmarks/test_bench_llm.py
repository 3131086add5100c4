"""`ltaa bench-llm` end to end against each provider's fake on loopback (small: two
scenarios' first tasks in one mode), and its refusals."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from app.cli import cli
from tests.fakes.fake_messages_api import Reply
from tests.fakes.llm_providers import Provider
from tests.fakes.scripted_reasoner import GARBAGE

N_TASKS = 6


@pytest.fixture
def runner(tmp_path: Path) -> CliRunner:
    return CliRunner(env={"LTAA_DATA_DIR": str(tmp_path / "data"), "COLUMNS": "120"})


def cells_of(report: str, title: str = "") -> list[list[str]]:
    """The `Every cell` rows of the section titled `title` (default: the first section)."""
    section = report.split(f"## {title}", 1)[1] if title else report
    body = section.split("### Every cell", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in body.splitlines() if line.startswith("| ")][1:]
    return [[cell.strip() for cell in row.strip("|").split("|")] for row in rows]


def test_bench_llm_writes_the_report_from_real_calls(
    runner: CliRunner, tmp_path: Path, provider: Provider
) -> None:
    out = tmp_path / "llm-benchmark.md"
    with provider.fake() as api:
        api.script(Reply.answer(GARBAGE))  # one retry at tier 1, in the first cell
        args: list[Any] = [
            "bench-llm",
            "--reasoner",
            provider.reasoner,
            "--model",
            provider.model,
            "--scenario",
            "baseline",
            "--scenario",
            "light_excels",
            "--mode",
            "balanced",
            "--tasks",
            str(N_TASKS),
            "--out",
            str(out),
        ]
        result = runner.invoke(cli, args, env=provider.env(api))
        served = api.answered()
        tokens = sum(api.tokens())
        base_url = api.base_url
    assert result.exit_code == 0, result.output
    report = out.read_text()
    assert f"endpoint `{base_url}`" in report and f"model `{provider.model}`" in report
    assert "1,088 tokens" in report and "4.14 s" in report
    cells = cells_of(report)
    # 2 scenarios x 1 mode x (all, contested) x (unguided, guided)
    assert len(cells) == 8
    assert [(c[0], c[2], c[3]) for c in cells[:4]] == [
        ("baseline", "all", "no"),
        ("baseline", "all", "yes"),
        ("baseline", "contested", "no"),
        ("baseline", "contested", "yes"),
    ]
    assert {c[4] for c in cells} == {"json_schema"}  # the default: structured replies
    asked = [int(re.search(r"\((\d+)/6\)", c[7]).group(1)) for c in cells]  # type: ignore[union-attr]
    assert [asked[i] for i in (0, 1, 4, 5)] == [N_TASKS] * 4  # scope all asks every task
    assert all(asked[i] <= N_TASKS for i in (2, 3, 6, 7))
    assert served == sum(asked) + 1  # every asked task once, plus the one retry
    assert cells[0][10] == "1 / 0 / 0" and cells[0][8] == "83%"  # 5 of 6 at the first try
    assert cells[0][9] == str(N_TASKS)  # the model's own answers decided every task
    assert {c[12] for c in cells} == {"0"} and {c[13] for c in cells} == {"-"}
    reported = sum(float(c[5].replace(",", "")) * N_TASKS for c in cells)
    assert reported == pytest.approx(tokens, abs=len(cells))  # tokens/task rounded per cell
    assert "Traceback" not in result.output


def test_a_run_writes_its_own_section_and_keeps_the_others(
    runner: CliRunner, tmp_path: Path, provider: Provider
) -> None:
    out = tmp_path / "llm-benchmark.md"
    with provider.fake() as api:
        base = ["bench-llm", "--reasoner", provider.reasoner, "--model", provider.model]
        base += ["--scenario", "baseline", "--mode", "balanced", "--tasks", "3", "--paper-only"]
        for fmt in ("markdown", "json_object", "markdown"):
            args = [*base, "--format", fmt, "--give-up", "0", "--out", str(out)]
            result = runner.invoke(cli, args, env=provider.env(api))
            assert result.exit_code == 0, result.output
    report = out.read_text()
    titles = [line for line in report.splitlines() if line.startswith("## ")]
    assert titles == [
        f"## {provider.model}: json_object, never given up",
        f"## {provider.model}: markdown, never given up",
    ]
    assert report.count("# LLM benchmark") == 1
    [row] = cells_of(report, titles[1][3:])
    assert row[2:5] == ["all", "no", "markdown"]


def test_bench_llm_without_a_configured_server_says_what_to_set(
    runner: CliRunner, tmp_path: Path
) -> None:
    result = runner.invoke(
        cli,
        ["bench-llm", "--out", str(tmp_path / "x.md")],
        env={"OPENAI_BASE_URL": "http://127.0.0.1:9/v1", "LTAA_OPENAI_BASE_URL": None},
    )
    assert result.exit_code == 1 and "LTAA_OPENAI_BASE_URL" in result.output
    assert not (tmp_path / "x.md").exists()


def test_bench_llm_refuses_the_rules_reasoner(runner: CliRunner) -> None:
    result = runner.invoke(cli, ["bench-llm", "--reasoner", "rules"])
    assert result.exit_code == 2 and "LLM reasoner" in result.output
