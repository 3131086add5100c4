"""llm_scope 'contested' (docs/reasoners.md#llm_scope-ask-the-model-only-where-it-matters): which
decisions ask the LLM, and that the clear-cut ones answered by the rules reasoner change nothing but
the bill."""

from __future__ import annotations

import pytest

from app.domain.modes import Mode
from app.domain.phases import Phase
from app.domain.tradeoff import rule_for
from app.reasoners.factory import make_reasoner
from app.reasoners.scope import ContestedOnlyReasoner, LLMScope, is_contested, scoped
from tests.fakes.scripted_reasoner import GARBAGE, ScriptedReasoner
from tests.support.ltaa_support import context, problem, run


def test_one_feasible_robot_is_clear_cut() -> None:
    assert not is_contested(context(feasible=(1,)))


def test_best_being_the_least_loaded_is_clear_cut() -> None:
    # heavy is both the most capable and, here, the least loaded.
    ctx = context(loads=(6, 5, 3))
    rule = rule_for(ctx)
    assert rule.best == rule.fewest == 2
    assert not is_contested(ctx)


@pytest.mark.parametrize(
    ("success", "contested"),
    [
        # light (load 3) is the least loaded; T = 13 (balanced, middle phase)
        ((0.5, 0.62, 0.9), False),  # gap 40: far above
        ((0.5, 0.7, 0.6), False),  # gap 20: 7 points above
        ((0.5, 0.66, 0.6), True),  # gap 16: 3 above
        ((0.5, 0.58, 0.55), True),  # gap 8: 5 below, on the edge
        ((0.5, 0.52, 0.51), False),  # gap 2: 11 below
    ],
)
def test_a_verdict_near_its_threshold_is_contested(
    success: tuple[float, ...], contested: bool
) -> None:
    ctx = context(success=success)
    rule = rule_for(ctx)
    assert (rule.fewest, rule.threshold) == (0, 13)
    assert is_contested(ctx) is contested, rule


def test_the_margin_is_in_points_either_side() -> None:
    ctx = context(success=(0.5, 0.7, 0.6))  # gap 20, T 13
    assert not is_contested(ctx, margin=5)
    assert is_contested(ctx, margin=7)
    assert not is_contested(ctx, margin=6.9)


def test_guidance_naming_another_robot_than_the_rule_is_contested() -> None:
    ctx = context(success=(0.5, 0.52, 0.9), loads=(3, 5, 6))  # gap 40: the rule says heavy
    assert rule_for(ctx).choice == 2 and not is_contested(ctx)
    assert is_contested(context(success=(0.5, 0.52, 0.9), guided_robot=0))
    assert not is_contested(context(success=(0.5, 0.52, 0.9), guided_robot=2))
    # Guidance the cap forbids is no disagreement the LLM could act on.
    assert not is_contested(context(success=(0.5, 0.52, 0.9), feasible=(1, 2), guided_robot=0))


def test_late_phase_thresholds_shift_the_band() -> None:
    late = context(phase=Phase.LATE, mode=Mode.BALANCED, success=(0.5, 0.7, 0.9))
    rule = rule_for(late)
    assert is_contested(late) is (abs(rule.gap - rule.threshold) <= 5)


def test_only_contested_decisions_reach_the_llm_and_the_rest_say_clear_cut() -> None:
    llm = ScriptedReasoner()
    contested = ContestedOnlyReasoner(llm)
    rec, _ = run(problem(), contested)
    asked = {c.task_index for c in llm.calls}
    firsts = [rec.attempt(t, 1) for t in range(36)]
    for t, attempt in enumerate(firsts):
        assert attempt is not None and attempt.reply is not None
        if t in asked:
            assert attempt.reply.model == "scripted"
            assert attempt.reply.extra["reasoner"] == "scripted"
        else:
            assert attempt.reply.model is None
            assert attempt.reply.extra == {"reasoner": "rules", "why": "clear-cut"}
    # docs/reasoners.md#llm_scope-ask-the-model-only-where-it-matters: about a fifth of the
    # baseline's balanced decisions are contested.
    assert 0 < len(asked) <= 0.4 * 36
    # The same answers under 'all': the same allocation.
    everything, _ = run(problem(), ScriptedReasoner())
    assert [d.robot for d in rec.decisions()] == [d.robot for d in everything.decisions()]


def test_a_contested_decision_is_retried_on_the_llm() -> None:
    probe, _ = run(problem(), ContestedOnlyReasoner(ScriptedReasoner()))
    first_contested = next(
        t
        for t in range(36)
        if probe.attempt(t, 1).reply.model is not None  # type: ignore[union-attr]
    )
    llm = ScriptedReasoner(script=[GARBAGE])
    rec, _ = run(problem(), ContestedOnlyReasoner(llm))
    assert [c.task_index for c in llm.calls[:2]] == [first_contested, first_contested]
    assert [c.tier for c in llm.calls[:2]] == [0, 1]
    assert rec.decisions()[first_contested].attempts == 2


def test_scoped_wraps_only_for_contested_and_the_factory_only_llms() -> None:
    llm = ScriptedReasoner()
    assert scoped(llm, "all") is llm
    assert isinstance(scoped(llm, LLMScope.CONTESTED), ContestedOnlyReasoner)
    with pytest.raises(ValueError):
        scoped(llm, "some")
    assert make_reasoner("rules", llm_scope="contested").name == "rules"
    assert not isinstance(make_reasoner("rules", llm_scope="contested"), ContestedOnlyReasoner)
