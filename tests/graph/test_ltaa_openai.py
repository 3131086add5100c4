"""The real openai SDK reasoner against a fake Chat Completions server on loopback.

Faults, resumes and replay run for both providers in the shared suites
(test_llm_faults.py, tests/reasoners/test_llm_runs.py, tests/runs/test_api_replay.py); this file
holds what is the openai reasoner's own: the request it sends, the settings it needs, and
that no OPENAI_* variable can send a request anywhere else.
"""

from __future__ import annotations

from collections.abc import Iterator

import openai
import pytest
from pydantic import SecretStr

from app.config import Settings
from app.domain.errors import DomainError
from app.graph.usage import usage_from_attempts
from app.reasoners.factory import make_reasoner
from app.reasoners.openai import NO_KEY, OpenAIReasoner
from app.reasoners.rules import RulesReasoner
from app.reasoners.transport import ReasonerRejectedError
from app.solvers.registry import get_solver
from tests.fakes.fake_chat_completions_api import FakeChatCompletionsAPI, Reply
from tests.support.ltaa_support import problem, run

# Every variable the SDK (3.51) or its HTTP client would read, pointed somewhere wrong.
HOSTILE_ENVIRONMENT = {
    "OPENAI_API_KEY": "sk-from-the-environment",
    "OPENAI_ADMIN_KEY": "sk-admin-from-the-environment",
    "OPENAI_ORG_ID": "org-from-the-environment",
    "OPENAI_PROJECT_ID": "proj-from-the-environment",
    "OPENAI_WEBHOOK_SECRET": "whsec-from-the-environment",
    "OPENAI_CUSTOM_HEADERS": "X-Leak: yes\nAuthorization: Bearer sk-custom",
    "HTTP_PROXY": "http://127.0.0.1:9",
    "HTTPS_PROXY": "http://127.0.0.1:9",
    "ALL_PROXY": "http://127.0.0.1:9",
    "NO_PROXY": "",
}


@pytest.fixture
def api() -> Iterator[FakeChatCompletionsAPI]:
    with FakeChatCompletionsAPI() as server:
        yield server


def reasoner(api: FakeChatCompletionsAPI, **kw: object) -> OpenAIReasoner:
    options = {"base_url": api.base_url, "model": "qwen-test", "timeout": 5.0, **kw}
    return OpenAIReasoner(**options)  # type: ignore[arg-type]


def test_answers_are_accepted_with_usage_latency_and_temperature(
    api: FakeChatCompletionsAPI,
) -> None:
    llm = reasoner(api, api_key="test-key")
    rec, _ = run(problem(n_tasks=3), llm)
    llm.close()
    assert all(d.attempts == 1 and not d.fallback for d in rec.decisions())
    rules, _ = run(problem(n_tasks=3), RulesReasoner())
    assert [d.robot for d in rec.decisions()] == [d.robot for d in rules.decisions()]
    usage = usage_from_attempts(rec.attempts())
    assert (usage.input_tokens, usage.output_tokens) == api.tokens() and usage.llm_calls == 3
    first = rec.attempts()[0]
    assert first.reply is not None and first.reply.model == "qwen-test"
    assert first.reply.latency_ms > 0 and first.reply.input_tokens > 0
    assert first.reply.extra["stop_reason"] == "stop"
    body = api.requests[0]
    assert body["messages"] == [
        {"role": "system", "content": first.system_prompt},
        {"role": "user", "content": first.user_prompt},
    ]
    assert body["temperature"] == 0.1 and body["max_tokens"] == 400  # the tier-0 cap
    assert body["_headers"]["authorization"] == "Bearer test-key"


def test_no_openai_variable_reaches_the_request(
    api: FakeChatCompletionsAPI, monkeypatch: pytest.MonkeyPatch
) -> None:
    with FakeChatCompletionsAPI() as decoy:
        monkeypatch.setenv("OPENAI_BASE_URL", decoy.base_url)
        for name, value in HOSTILE_ENVIRONMENT.items():
            monkeypatch.setenv(name, value)
        llm = reasoner(api)  # no key configured: a local server
        run(problem(n_tasks=1), llm)
        llm.close()
        assert decoy.requests == []
    [request] = api.requests
    headers = request["_headers"]
    assert headers["authorization"] == f"Bearer {NO_KEY}"
    leaked = {"openai-organization", "openai-project", "x-leak"} & headers.keys()
    assert leaked == set(), headers


def test_a_redirect_is_not_followed(api: FakeChatCompletionsAPI) -> None:
    with FakeChatCompletionsAPI() as elsewhere:
        target = f"{elsewhere.base_url}/chat/completions"
        api.script(Reply(status=307, headers={"location": target}))
        with pytest.raises(ReasonerRejectedError) as err:
            run(problem(n_tasks=1), reasoner(api, transport_retries=0))
        assert elsewhere.requests == []
    # A server that sends the prompt elsewhere is misconfigured: the run stops, saying so.
    assert "HTTP 307" in err.value.message and "LTAA_OPENAI_BASE_URL" in err.value.message


def test_a_rejected_key_ends_the_run_naming_the_setting(api: FakeChatCompletionsAPI) -> None:
    api.script(Reply.error(401, retry_after=None))
    with pytest.raises(ReasonerRejectedError) as err:
        run(problem(n_tasks=1), reasoner(api))
    assert err.value.status_code == 502 and "LTAA_OPENAI_API_KEY" in err.value.message
    assert isinstance(err.value.__cause__, openai.AuthenticationError)


def test_an_unknown_model_through_allocate_names_the_option(
    api: FakeChatCompletionsAPI, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("LTAA_OPENAI_BASE_URL", api.base_url)
    api.script(Reply.error(404, retry_after=None))
    with pytest.raises(DomainError) as err:
        get_solver("ltaa", settings=Settings()).solve(
            problem(n_tasks=1), options={"reasoner": "openai", "model": "no"}
        )
    assert err.value.field == "options.model" and err.value.status_code == 422
    assert err.value.code == "unknown_model"


def test_ltaa_solver_with_openai_options(
    api: FakeChatCompletionsAPI, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("LTAA_OPENAI_BASE_URL", api.base_url)
    monkeypatch.setenv("LTAA_OPENAI_MODEL", "from-settings")
    solution = get_solver("ltaa", settings=Settings()).solve(
        problem(n_tasks=3), options={"reasoner": "openai", "temperature": 0.3}
    )
    assert solution.usage.llm_calls == 3
    assert (solution.usage.input_tokens, solution.usage.output_tokens) == api.tokens()
    assert {r["model"] for r in api.requests} == {"from-settings"}
    assert {r["temperature"] for r in api.requests} == {0.3}


def test_the_factory_needs_a_base_url_and_a_model(monkeypatch: pytest.MonkeyPatch) -> None:
    for name, value in HOSTILE_ENVIRONMENT.items():
        monkeypatch.setenv(name, value)
    monkeypatch.setenv("OPENAI_BASE_URL", "http://127.0.0.1:9/v1")
    bare = Settings(openai_base_url=None, openai_model=None, openai_api_key=None)
    with pytest.raises(DomainError) as err:
        make_reasoner("openai", settings=bare)
    assert (err.value.field, err.value.code) == ("reasoner", "missing_setting")
    assert "LTAA_OPENAI_BASE_URL" in err.value.message
    with_url = bare.model_copy(update={"openai_base_url": "http://127.0.0.1:9/v1"})
    with pytest.raises(DomainError, match="LTAA_OPENAI_MODEL"):
        make_reasoner("openai", settings=with_url)
    configured = with_url.model_copy(
        update={
            "openai_model": "m",
            "openai_api_key": SecretStr("k"),
            "openai_timeout_s": 7.0,
            "openai_max_transport_retries": 5,
        }
    )
    built = make_reasoner("openai", settings=configured, model="override")
    assert isinstance(built, OpenAIReasoner)
    assert (built.model, built.transport_retries, built.temperature) == ("override", 5, 0.1)
    assert built.base_url == "http://127.0.0.1:9/v1"
    built.close()


def test_a_base_url_must_be_http() -> None:
    with pytest.raises(ValueError, match="openai_base_url"):
        Settings(openai_base_url="file:///etc/passwd")


def test_a_completion_without_choices_is_a_failed_attempt(api: FakeChatCompletionsAPI) -> None:
    empty = b'{"id": "c", "object": "chat.completion", "created": 1, "model": "m", "choices": []}'
    api.script(Reply(body=empty))
    rec, _ = run(problem(n_tasks=1), reasoner(api))
    failed, fixed = rec.attempts(0)
    assert failed.reply is not None and "no choices" in str(failed.reply.extra["error"])
    assert failed.reply.model is None and fixed.accepted and fixed.tier == 1
