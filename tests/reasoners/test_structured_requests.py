"""What each SDK-backed reasoner sends when a run asks for structured replies
(docs/reasoners.md#structured-replies), through the real SDKs against the loopback fakes:
Chat Completions `response_format` in the json_schema dialect (or json_object + schema for
the servers that refuse it, learnt from the refusal without ending the run), Anthropic's
forced tool use; the per-tier output-token caps; and a markdown run asks as it always did."""

from __future__ import annotations

import json

import pytest

from app.graph.reply_schema import DECISION_SCHEMA
from app.graph.state import ModelUse
from app.reasoners.anthropic import AnthropicReasoner
from app.reasoners.openai import OpenAIReasoner
from app.reasoners.structured import ReplyFormat
from tests.fakes.fake_chat_completions_api import FakeChatCompletionsAPI
from tests.fakes.fake_messages_api import FakeMessagesAPI, Reply
from tests.fakes.scripted_reasoner import GARBAGE
from tests.support.ltaa_support import problem, reply_of, run

STRUCTURED = ModelUse(reply_format=ReplyFormat.JSON_SCHEMA)


def openai_reasoner(api: FakeChatCompletionsAPI, fmt: ReplyFormat, **kw: object) -> OpenAIReasoner:
    return OpenAIReasoner(
        base_url=api.base_url,
        model="local-test",
        timeout=5.0,
        reply_format=fmt,
        **kw,  # type: ignore[arg-type]
    )


@pytest.mark.parametrize("fmt", [ReplyFormat.JSON_SCHEMA, ReplyFormat.JSON_OBJECT])
def test_chat_completions_asks_in_the_dialect_the_setting_names(fmt: ReplyFormat) -> None:
    with FakeChatCompletionsAPI() as api:
        llm = openai_reasoner(api, fmt)
        rec, _ = run(problem(n_tasks=3), llm, model_use=ModelUse(reply_format=fmt))
        llm.close()
    assert all(d.attempts == 1 and not d.fallback for d in rec.decisions())
    body = api.requests[0]["response_format"]
    if fmt is ReplyFormat.JSON_SCHEMA:
        assert body["type"] == "json_schema" and body["json_schema"]["name"] == DECISION_SCHEMA
        schema = body["json_schema"]["schema"]
    else:
        assert body["type"] == "json_object"
        schema = body["schema"]
    assert schema["properties"]["decision"]["enum"]
    first = rec.attempts()[0]
    assert json.loads(reply_of(first).text)["decision"] in schema["properties"]["decision"]["enum"]
    assert reply_of(first).extra["response_format"] == fmt.value
    assert '"decision"' in first.user_prompt and "**Decision**" not in first.user_prompt


def test_a_server_refusing_json_schema_is_asked_in_json_object_for_the_rest_of_the_run() -> None:
    with FakeChatCompletionsAPI(refuse_json_schema=True) as api:
        llm = openai_reasoner(api, ReplyFormat.JSON_SCHEMA, transport_retries=1)
        rec, _ = run(problem(n_tasks=3), llm, model_use=STRUCTURED)
        llm.close()
    # The refusal (a 500, retried once by the SDK) costs the first call two requests; then
    # every call asks in llama-cpp-python's dialect and is answered.
    kinds = [r["response_format"]["type"] for r in api.requests]
    assert kinds == ["json_schema", "json_schema", "json_object", "json_object", "json_object"]
    assert all(d.attempts == 1 and not d.fallback for d in rec.decisions())
    assert {reply_of(a).extra["response_format"] for a in rec.attempts()} == {"json_object"}


def test_a_400_naming_the_format_is_no_refusal_of_the_run() -> None:
    """OpenAI answers a schema it cannot take with a 400 naming response_format; that
    refusal of the dialect must not end the run, as a 400 otherwise does."""
    with FakeChatCompletionsAPI() as api:
        refusal = Reply.error(400, retry_after=None)
        refusal.text = "Invalid parameter: 'response_format' of type 'json_schema' is not supported"
        api.script(refusal)
        llm = openai_reasoner(api, ReplyFormat.JSON_SCHEMA)
        rec, _ = run(problem(n_tasks=2), llm, model_use=STRUCTURED)
        llm.close()
    assert [r["response_format"]["type"] for r in api.requests] == ["json_schema"] + [
        "json_object"
    ] * 2
    assert not any(d.fallback for d in rec.decisions())


def test_claude_is_forced_to_use_the_decision_tool() -> None:
    with FakeMessagesAPI() as api:
        llm = AnthropicReasoner(api_key="k", model="claude-test", base_url=api.base_url)
        rec, _ = run(problem(n_tasks=2), llm, model_use=STRUCTURED)
        llm.close()
    body = api.requests[0]
    assert body["tool_choice"] == {"type": "tool", "name": DECISION_SCHEMA}
    [tool] = body["tools"]
    assert tool["name"] == DECISION_SCHEMA and tool["input_schema"]["required"]
    assert all(d.attempts == 1 and not d.fallback for d in rec.decisions())
    assert reply_of(rec.attempts()[0]).extra["response_format"] == "tool_use"


def test_each_tier_asks_within_its_own_cap() -> None:
    with FakeChatCompletionsAPI() as api:
        api.script(*[Reply.answer(GARBAGE)] * 3)  # tiers 0-2 fail, tier 3 is answered
        llm = openai_reasoner(api, ReplyFormat.JSON_OBJECT, max_tokens=(300, 310, 320, 330))
        run(problem(n_tasks=1), llm, model_use=ModelUse(reply_format=ReplyFormat.JSON_OBJECT))
        llm.close()
    assert [r["max_tokens"] for r in api.requests] == [300, 310, 320, 330]


def test_a_markdown_run_sends_no_format_at_all() -> None:
    with FakeChatCompletionsAPI() as api, FakeMessagesAPI() as claude:
        for llm in (
            openai_reasoner(api, ReplyFormat.JSON_SCHEMA),
            AnthropicReasoner(api_key="k", model="claude-test", base_url=claude.base_url),
        ):
            run(problem(n_tasks=1), llm)  # ModelUse() asks in markdown
            llm.close()
    assert "response_format" not in api.requests[0]
    assert "tools" not in claude.requests[0] and "tool_choice" not in claude.requests[0]
    assert "**Decision**" in api.requests[0]["messages"][-1]["content"]
