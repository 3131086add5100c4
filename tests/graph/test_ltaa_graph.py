"""The whole graph: rules runs on every scenario and mode, retry tiers, fallback, limits."""

from __future__ import annotations

import pytest
from langgraph.checkpoint.memory import InMemorySaver

from app.domain.catalog import scenarios
from app.domain.metrics import workload
from app.domain.modes import Mode
from app.graph.builder import build_graph
from app.graph.memory_recorder import MemoryRecorder
from app.graph.recorder import RunCancelled
from app.graph.runner import recursion_limit, run_graph
from app.graph.state import GraphContext
from app.graph.usage import usage_from_attempts
from app.reasoners.rules import RulesReasoner
from tests.fakes.scripted_reasoner import GARBAGE, ScriptedReasoner, poor_answer
from tests.support.ltaa_support import problem, run


@pytest.mark.parametrize("mode", list(Mode))
@pytest.mark.parametrize("name", sorted(scenarios()))
def test_rules_run_scores_at_least_090_everywhere_and_respects_the_cap(
    name: str, mode: Mode
) -> None:
    prob = problem(name, mode)
    rec, final = run(prob)
    decisions = rec.decisions()
    assert [d.task_index for d in decisions] == list(range(36))
    assert final["done"] and final["task_index"] == 36
    assert all(d.quality >= 0.9 for d in decisions), [d.quality for d in decisions]
    assert all(d.attempts == 1 and not d.fallback for d in decisions)
    loads = workload([d.robot for d in decisions], 3)
    assert prob.cap.respected_by(loads) and final["loads"] == loads
    assert decisions[-1].loads_after == loads
    assert usage_from_attempts(rec.attempts()).llm_calls == 0  # zero tokens, no LLM


def test_garbage_escalates_through_every_tier_then_falls_back() -> None:
    prob = problem(n_tasks=2)
    reasoner = ScriptedReasoner(then=GARBAGE)
    rec, _ = run(prob, reasoner)
    attempts = rec.attempts(0)
    assert [a.tier for a in attempts] == [0, 1, 2, 3]
    assert len({a.user_prompt for a in attempts}) == 4
    assert [c.tier for c in reasoner.calls] == [0, 1, 2, 3] * 2
    for d in rec.decisions():
        assert d.fallback and d.attempts == 4 and len(d.failure_log) == 4
        assert all("no parseable decision" in line for line in d.failure_log)
        assert [line.split(":")[0] for line in d.failure_log] == [
            "attempt 1 (tier 0)",
            "attempt 2 (tier 1)",
            "attempt 3 (tier 2)",
            "attempt 4 (tier 3)",
        ]
        assert d.reasoning.startswith("Rule-based choice")
    usage = usage_from_attempts(rec.attempts())
    assert (usage.llm_calls, usage.input_tokens, usage.output_tokens) == (8, 800, 400)


def test_fallback_is_the_rules_choice() -> None:
    prob = problem(n_tasks=6)
    fallback, _ = run(prob, ScriptedReasoner(then=GARBAGE), max_retries=0)
    rules, _ = run(prob)
    assert [d.robot for d in fallback.decisions()] == [d.robot for d in rules.decisions()]
    assert all(d.fallback and d.attempts == 1 for d in fallback.decisions())


def test_poor_answer_is_rejected_then_fixed_at_tier_1() -> None:
    prob = problem(n_tasks=3)
    reasoner = ScriptedReasoner([poor_answer])
    rec, _ = run(prob, reasoner)
    first, second = rec.attempts(0)
    assert not first.accepted and first.quality is not None and first.quality < 0.6
    assert first.hard_invalid is None and first.feedback is not None
    assert first.feedback.startswith(f"Q={first.quality:.2f} below the threshold 0.60")
    assert "success-rate accuracy" in first.feedback and "Fix:" in first.feedback
    assert second.tier == 1 and second.accepted and first.feedback in second.user_prompt
    d = rec.decisions()[0]
    assert d.attempts == 2 and not d.fallback and len(d.failure_log) == 1
    assert d.quality == second.quality


def test_quality_threshold_is_configurable() -> None:
    prob = problem(n_tasks=2)
    rec, _ = run(prob, ScriptedReasoner([poor_answer, poor_answer]), threshold=0.1)
    assert all(d.attempts == 1 and not d.fallback for d in rec.decisions())


def test_worst_case_fits_the_recursion_limit_exactly() -> None:
    assert recursion_limit(36, 3) == 21 * 36 + 1
    assert recursion_limit(10, 0) == 91
    # Every task exhausts its retries: (9 + 4 * max_retries) super-steps each.
    rec, _ = run(problem(n_tasks=12), ScriptedReasoner(then=GARBAGE), max_retries=2)
    assert len(rec.decisions()) == 12 and all(d.attempts == 3 for d in rec.decisions())


def test_guidance_is_followed_and_counted_compliant() -> None:
    prob = problem(n_tasks=3, mode=Mode.SUCCESS_FOCUSED)
    rec = MemoryRecorder()
    ctx = GraphContext(
        problem=prob, reasoner=RulesReasoner(), recorder=rec, guidance=lambda t, loads: 1
    )  # always the medium robot
    run_graph(build_graph(InMemorySaver()), ctx, "guided", resume=False)
    for d in rec.decisions():
        assert d.robot == 1 and d.quality >= 0.9
        assert "optimizer's guidance" in d.reasoning


def test_cancellation_stops_at_the_next_node() -> None:
    prob = problem()
    rec = MemoryRecorder(before_reason_hook=lambda t, a: rec.cancel() if t == 5 else None)
    ctx = GraphContext(problem=prob, reasoner=RulesReasoner(), recorder=rec)
    with pytest.raises(RunCancelled):
        run_graph(build_graph(InMemorySaver()), ctx, "cancel", resume=False)
    assert [d.task_index for d in rec.decisions()] == [0, 1, 2, 3, 4]


def test_run_graph_refuses_to_restart_a_thread_and_resumes_a_fresh_one() -> None:
    prob = problem(n_tasks=2)
    graph = build_graph(InMemorySaver())
    ctx = GraphContext(problem=prob, reasoner=RulesReasoner(), recorder=MemoryRecorder())
    # Resuming a thread that never reached a checkpoint starts it.
    assert run_graph(graph, ctx, "t", resume=True)["done"]
    with pytest.raises(ValueError, match="already has checkpoints"):
        run_graph(graph, ctx, "t", resume=False)
    # Resuming a finished thread does nothing more.
    assert run_graph(graph, ctx, "t", resume=True)["task_index"] == 2
    assert len(ctx.recorder.decisions()) == 2


def test_rules_reasoner_never_claims_to_be_an_llm() -> None:
    prob = problem(n_tasks=4)
    rec, _ = run(prob)
    for a in rec.attempts():
        assert a.reply is not None and a.reply.model is None and a.reply.input_tokens == 0
        assert "not a language model" in a.reply.text
