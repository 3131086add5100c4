"""The real anthropic SDK reasoner against a fake Messages API on loopback (no network)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import anthropic
import pytest
from pydantic import SecretStr

from app.config import Settings
from app.domain.errors import DomainError
from app.graph.memory_recorder import MemoryRecorder
from app.graph.prompts import prompt_for
from app.graph.usage import usage_from_attempts
from app.graph.validation import validate_text
from app.reasoners.anthropic import SAMPLING_API_VERSION, AnthropicReasoner, ReasonerRejectedError
from app.reasoners.factory import make_reasoner
from app.reasoners.rules import RulesReasoner
from app.solvers.registry import get_solver
from tests.fakes.fake_messages_api import FakeMessagesAPI, Reply, answer_from_prompt
from tests.fakes.scripted_reasoner import GARBAGE
from tests.support.ltaa_support import context, problem, reply_of, run

POOR = "**Decision**: Light Robot\n**Expected Success**: 3%"


@pytest.fixture
def api() -> Iterator[FakeMessagesAPI]:
    with FakeMessagesAPI() as server:
        yield server


def reasoner(api: FakeMessagesAPI, **kw: Any) -> AnthropicReasoner:
    options: dict[str, Any] = {
        "api_key": "test-key",
        "base_url": api.base_url,
        "timeout": 5.0,
        "transport_retries": 3,
        **kw,
    }
    return AnthropicReasoner(**options)


def assert_usage_matches_server(rec: MemoryRecorder, api: FakeMessagesAPI) -> None:
    usage = usage_from_attempts(rec.attempts())
    assert (usage.input_tokens, usage.output_tokens) == api.tokens()
    assert usage.llm_calls == api.answered()


def test_good_answers_are_accepted_at_attempt_1(api: FakeMessagesAPI) -> None:
    rec, _ = run(problem(n_tasks=3), reasoner(api))
    assert all(d.attempts == 1 and not d.fallback for d in rec.decisions())
    rules, _ = run(problem(n_tasks=3), RulesReasoner())
    assert [d.robot for d in rec.decisions()] == [d.robot for d in rules.decisions()]
    assert_usage_matches_server(rec, api)
    first = rec.attempts()[0]
    reply = reply_of(first)
    assert reply.model == "claude-sonnet-4-6" and reply.latency_ms > 0
    assert reply.input_tokens > 0 and reply.transport_retries == 0
    body = api.requests[0]
    assert body["messages"][0]["content"] == first.user_prompt
    assert body["system"] == first.system_prompt
    assert body["temperature"] == 0.1  # docs/reasoners.md#the-anthropic-reasoner-claude
    assert body["_headers"]["anthropic-version"] == SAMPLING_API_VERSION


def test_without_temperature_no_sampling_parameter_is_sent(api: FakeMessagesAPI) -> None:
    run(problem(n_tasks=1), reasoner(api, temperature=None))
    body = api.requests[0]
    assert "temperature" not in body
    assert body["_headers"]["anthropic-version"] != SAMPLING_API_VERSION


def test_poor_answer_is_rejected_then_fixed_at_tier_1(api: FakeMessagesAPI) -> None:
    api.script(Reply.answer(POOR))
    rec, _ = run(problem(n_tasks=2), reasoner(api))
    first, second = rec.attempts(0)
    assert not first.accepted and first.hard_invalid is None
    assert first.quality is not None and first.quality < 0.6
    assert second.tier == 1 and second.accepted
    assert "Your previous answer scored" in api.requests[1]["messages"][0]["content"]
    assert rec.decisions()[0].attempts == 2
    assert_usage_matches_server(rec, api)


def test_garbage_every_time_falls_back_with_a_failure_log(api: FakeMessagesAPI) -> None:
    api.script(*[Reply.answer(GARBAGE)] * 4)
    rec, _ = run(problem(n_tasks=1), reasoner(api))
    [d] = rec.decisions()
    assert d.fallback and d.attempts == 4 and len(d.failure_log) == 4
    assert all("no parseable decision" in line for line in d.failure_log)
    assert [r["_headers"]["x-stainless-retry-count"] for r in api.requests] == ["0"] * 4
    assert_usage_matches_server(rec, api)


def test_transport_errors_are_retried_by_the_sdk_then_succeed(api: FakeMessagesAPI) -> None:
    api.script(
        Reply.error(429, retry_after=0.05),
        Reply.from_prompt(),  # task 0: 429 then ok
        Reply.error(500, retry_after=None),
        Reply.from_prompt(),  # task 1: 500, SDK backoff
        Reply.slow(1.5),
        Reply.from_prompt(),  # task 2: client timeout (0.5 s) then ok
    )
    rec, _ = run(problem(n_tasks=3), reasoner(api, timeout=0.5))
    assert all(d.attempts == 1 and not d.fallback for d in rec.decisions())
    assert [reply_of(a).transport_retries for a in rec.attempts()] == [1, 1, 1]
    assert [r["_headers"]["x-stainless-retry-count"] for r in api.requests] == [
        "0",
        "1",
        "0",
        "1",
        "0",
        "1",
    ]
    assert [s.status for s in api.served[:4]] == [429, 200, 500, 200]
    assert_usage_matches_server(rec, api)  # the timed-out reply was never delivered


def test_transport_giving_up_is_a_failed_attempt_not_a_failed_run(api: FakeMessagesAPI) -> None:
    api.script(*[Reply.error(529, retry_after=0.01)] * 2, Reply.from_prompt())
    rec, _ = run(problem(n_tasks=1), reasoner(api, transport_retries=1))
    first, second = rec.attempts(0)
    error = reply_of(first).extra["error"]
    assert isinstance(error, str) and "HTTP 529" in error
    assert first.hard_invalid is not None and "no reply" in first.hard_invalid
    assert reply_of(first).model is None  # nothing answered: not an LLM call
    assert second.accepted and second.tier == 1
    assert_usage_matches_server(rec, api)


def test_a_rejected_key_ends_the_run(api: FakeMessagesAPI) -> None:
    api.script(Reply.error(401, retry_after=None))
    with pytest.raises(ReasonerRejectedError) as err:
        run(problem(n_tasks=1), reasoner(api))
    assert err.value.status_code == 502 and "ANTHROPIC_API_KEY" in err.value.message
    assert isinstance(err.value.__cause__, anthropic.AuthenticationError)


def test_an_unknown_model_through_allocate_names_the_option(
    api: FakeMessagesAPI, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("LTAA_ANTHROPIC_API_KEY", "test")
    monkeypatch.setenv("LTAA_ANTHROPIC_BASE_URL", api.base_url)
    api.script(Reply.error(404, retry_after=None))
    with pytest.raises(DomainError) as err:
        get_solver("ltaa", settings=Settings()).solve(
            problem(n_tasks=1), options={"reasoner": "anthropic", "model": "nope"}
        )
    assert err.value.field == "options.model" and err.value.status_code == 422


def test_the_fake_answers_every_prompt_tier_well() -> None:
    ctx = context()
    prompts = [prompt_for(ctx, tier, feedback="- fix it", quality=0.3) for tier in range(4)]
    for text in prompts:
        assert validate_text(answer_from_prompt(text), ctx).quality >= 0.9


def test_ltaa_solver_with_anthropic_options(
    api: FakeMessagesAPI, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The key and endpoint come from the server's settings, never from the request.
    monkeypatch.setenv("LTAA_ANTHROPIC_API_KEY", "test")
    monkeypatch.setenv("LTAA_ANTHROPIC_BASE_URL", api.base_url)
    solution = get_solver("ltaa", settings=Settings()).solve(
        problem(n_tasks=3),
        options={"reasoner": "anthropic", "model": "claude-test", "temperature": 0.2},
    )
    assert solution.usage.llm_calls == 3
    assert (solution.usage.input_tokens, solution.usage.output_tokens) == api.tokens()
    assert {r["model"] for r in api.requests} == {"claude-test"}
    assert {r["temperature"] for r in api.requests} == {0.2}


class FakeSettings:
    # Typed as ReasonerSettings declares them: its attributes are mutable, hence invariant.
    anthropic_api_key: SecretStr | None = SecretStr("from-settings")
    anthropic_base_url: str | None = "http://127.0.0.1:9"
    anthropic_timeout_s = 12.0
    anthropic_max_transport_retries = 5
    default_model = "claude-settings"
    openai_base_url: str | None = None
    openai_api_key: SecretStr | None = None
    openai_model: str | None = None
    openai_timeout_s = 60.0
    openai_max_transport_retries = 3
    llm_max_tokens: list[int] = [300, 310, 320, 330]  # noqa: RUF012


def test_factory(monkeypatch: pytest.MonkeyPatch) -> None:
    for var in ("ANTHROPIC_API_KEY", "LTAA_ANTHROPIC_API_KEY"):
        monkeypatch.delenv(var, raising=False)
    assert isinstance(make_reasoner("rules"), RulesReasoner)
    with pytest.raises(DomainError) as err:
        make_reasoner("anthropic")
    assert err.value.field == "reasoner" and err.value.code == "missing_api_key"
    assert "ANTHROPIC_API_KEY" in err.value.message
    assert "LTAA_ANTHROPIC_API_KEY" in err.value.message
    with pytest.raises(DomainError, match="unknown reasoner 'llama'"):
        make_reasoner("llama")
    r = make_reasoner("anthropic", settings=FakeSettings(), model="claude-override")
    assert isinstance(r, AnthropicReasoner)
    assert (r.model, r.transport_retries, r.temperature) == ("claude-override", 5, 0.1)
    assert [r.caps.at(tier) for tier in range(5)] == [300, 310, 320, 330, 330]
    monkeypatch.setenv("LTAA_ANTHROPIC_API_KEY", "from-env")
    assert isinstance(make_reasoner("anthropic"), AnthropicReasoner)
