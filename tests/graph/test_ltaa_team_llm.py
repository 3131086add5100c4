"""Team decisions over the official SDKs (docs/allocation.md#teams, docs/reasoners.md): the
anthropic and openai reasoners against the loopback fakes form teams, their replies go
through the same **Team** parser and validation, and a hard-invalid team is retried."""

from __future__ import annotations

import pytest

from app.graph.prompts import prompt_for
from app.graph.recorder import DecisionRecord
from app.graph.validation import validate_text
from app.reasoners.anthropic import AnthropicReasoner
from app.reasoners.openai import OpenAIReasoner
from app.reasoners.rules import RulesReasoner
from tests.fakes.fake_chat_completions_api import FakeChatCompletionsAPI
from tests.fakes.fake_messages_api import FakeMessagesAPI, Reply, answer_from_prompt
from tests.graph.test_ltaa_teams import CTX, PROBLEM, ctx_at
from tests.support.ltaa_support import reply_of, run


def test_the_fake_answers_every_tier_of_a_team_prompt_with_a_valid_team() -> None:
    for ctx in (CTX, ctx_at(PROBLEM, 0, [0, 0, 0, 0]), ctx_at(PROBLEM, 1, [2, 0, 2, 0], [2, 3])):
        for tier in range(4):
            text = prompt_for(ctx, tier, feedback="- fix it", quality=0.3)
            verdict = validate_text(answer_from_prompt(text), ctx)
            assert verdict.accepted and verdict.quality >= 0.9, verdict.notes
            assert ctx.team is not None and verdict.team in (ctx.team.best, ctx.team.guided)


def _teams(decisions: list[DecisionRecord]) -> list[list[dict[str, str]] | None]:
    return [d.team for d in decisions]


def test_an_anthropic_sdk_run_forms_teams() -> None:
    with FakeMessagesAPI() as api:
        reasoner = AnthropicReasoner(
            api_key="test-key", base_url=api.base_url, timeout=5.0, transport_retries=1
        )
        rec, _ = run(PROBLEM, reasoner)
        assert api.answered() == 4
    decisions = rec.decisions()
    assert all(d.attempts == 1 and not d.fallback for d in decisions)
    rules, _ = run(PROBLEM, RulesReasoner())
    assert _teams(decisions) == _teams(rules.decisions())
    assert [len(d.team or []) for d in decisions] == [2, 2, 0, 0]
    first = rec.attempts()[0]
    assert "**Team**" in reply_of(first).text and first.parsed is not None
    assert [m["robot"] for m in first.parsed["team"]] == ["crane", "lifter"]


def test_an_openai_sdk_run_forms_teams() -> None:
    with FakeChatCompletionsAPI() as api:
        reasoner = OpenAIReasoner(base_url=api.base_url, model="qwen-test", timeout=5.0)
        rec, _ = run(PROBLEM, reasoner)
    decisions = rec.decisions()
    assert all(not d.fallback for d in decisions)
    rules, _ = run(PROBLEM, RulesReasoner())
    assert _teams(decisions) == _teams(rules.decisions())


@pytest.mark.parametrize(
    ("bad", "why"),
    [
        ("**Decision**: Crane\n**Team**:\n- heavy: Crane — 90%.", "not covered"),
        (
            "**Decision**: Crane\n**Team**:\n- heavy: Crane — 90%.\n- heavy: Crane — 90%.",
            "two units",
        ),
    ],
)
def test_a_hard_invalid_team_is_retried_with_feedback(bad: str, why: str) -> None:
    with FakeMessagesAPI() as api:
        api.script(Reply.answer(bad))
        reasoner = AnthropicReasoner(
            api_key="test-key", base_url=api.base_url, timeout=5.0, transport_retries=1
        )
        rec, _ = run(PROBLEM, reasoner)
    first = rec.decisions()[0]
    assert first.attempts == 2 and not first.fallback
    attempt = rec.attempts()[0]
    assert attempt.quality == 0.0 and why in (attempt.hard_invalid or "")
    assert attempt.feedback is not None and "Hard invalid" in attempt.feedback
