"""Issue 15's offline acceptance, computed from the graph on all 12 scenario x mode cells:
with a fake that always follows the optimizer's guidance, 'contested' + guidance keeps
regret 0; with the rules-equivalent fake, 'contested' gives the same allocation as 'all';
on baseline / balanced at most 40% of the decisions ask the model."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.domain.modes import Mode
from app.reasoners.scope import LLMScope
from benchmarks import llm_scope, report
from benchmarks.common import Section
from benchmarks.llm_scope import GuidanceFollower, RulesEquivalent, cells, scope_run

CELLS = cells()


def test_there_are_twelve_cells() -> None:
    assert len(CELLS) == 12 and len({name for name, _ in CELLS}) == 4


@pytest.mark.parametrize(("name", "mode"), CELLS, ids=[f"{n}-{m.value}" for n, m in CELLS])
def test_contested_changes_the_bill_not_the_plan(name: str, mode: Mode) -> None:
    guided = scope_run(name, mode, LLMScope.CONTESTED, guided=True, fake=GuidanceFollower())
    assert guided.regret == pytest.approx(0.0, abs=1e-9)
    for with_guidance in (False, True):
        everything = scope_run(name, mode, LLMScope.ALL, guided=with_guidance)
        contested = scope_run(name, mode, LLMScope.CONTESTED, guided=with_guidance)
        assert contested.assignment == everything.assignment
        assert everything.llm_tasks == everything.n_tasks == 36
        assert contested.llm_calls <= everything.llm_calls


def test_baseline_balanced_asks_the_model_for_at_most_40_percent() -> None:
    run = scope_run("baseline", Mode.BALANCED, LLMScope.CONTESTED)
    assert 0 < run.share <= 0.4
    assert run.est_tokens == run.llm_calls * 1_088


def test_the_guidance_follower_needs_guidance() -> None:
    with pytest.raises(ValueError, match="needs optimizer guidance"):
        scope_run("baseline", Mode.BALANCED, LLMScope.ALL, fake=GuidanceFollower())


def test_a_partial_bench_replaces_only_its_sections(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    existing = "# Benchmarks\n\nGenerated once.\n\n## Kept\n\nold figures\n\n## Mine\n\nstale\n"
    (tmp_path / "benchmarks.md").write_text(existing)
    monkeypatch.setattr(report, "DOCS", tmp_path)
    monkeypatch.setattr(report, "IMG", tmp_path / "img")
    monkeypatch.setattr(llm_scope, "run", lambda: Section("Mine", "fresh\n"))
    report.main(["benchmarks.llm_scope"])
    written = (tmp_path / "benchmarks.md").read_text()
    assert "## Kept\n\nold figures\n" in written and "stale" not in written
    assert "## Mine\n\nfresh\n" in written and written.startswith("# Benchmarks\n\nGenerated once.")
    assert written.index("## Kept") < written.index("## Mine")


def test_rules_equivalent_is_counted() -> None:
    fake = RulesEquivalent()
    scope_run("baseline", Mode.BALANCED, LLMScope.ALL, fake=fake)
    assert fake.calls == 36 and fake.tasks == set(range(36))
