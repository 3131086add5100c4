"""The LTAA graph against a real language model (docs/reasoners.md#a-local-model):
llama-cpp-python's OpenAI-compatible server with SmolLM2-135M-Instruct, through the real
`openai` SDK, a real uvicorn server of ours, SQLite and the checkpointer, with the default
settings but the give-up rule's (structured replies asked in json_schema, which this server
refuses: the run asks in its json_object dialect instead).

A weak model: most of its answers fail validation and fall back to the rule, which is the
point of the validator. What must hold whatever it answers: the run completes, every
stored decision is valid, the usage is what the server reported, the record verifies, and
a run killed mid-way and restarted asks the server nothing it had answered before.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from llama_cpp import Llama

from app.graph.pause import PausePoint
from app.graph.validation import DEFAULT_QUALITY_THRESHOLD
from tests.support.model_server import ModelServer, model_file
from tests.support.server import Server

pytestmark = [pytest.mark.e2e, pytest.mark.model]

# Killed the moment task 0's first reply is recorded: the resumed run must use that reply,
# not ask for it again.
KILLED_AT = PausePoint(0, "reason", after=True)
# Two attempts a task and given up after two failed tasks in a row (the defaults are 4 and
# 3): each call of this model costs seconds on a CI machine whose cores the suite shares.
MAX_RETRIES = 1
GIVE_UP_AFTER = 2


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ModelServer]:
    with ModelServer.start(tmp_path_factory.mktemp("model") / "llama-server.log") as server:
        yield server


def _chat_tokens(tokenizer: Llama, system: str, user: str) -> int:
    """What the server counts as a request's prompt: the model's chat template, tokenized
    (an independent count of the `prompt_tokens` it reports)."""
    text = (
        f"<|im_start|>system\n{system}<|im_end|>\n<|im_start|>user\n{user}<|im_end|>\n"
        "<|im_start|>assistant\n"
    )
    return len(tokenizer.tokenize(text.encode(), add_bos=False, special=True))


@pytest.mark.timeout(1200)
def test_a_durable_run_killed_mid_way_completes_valid_and_asks_nothing_twice(
    tmp_path: Path, model: ModelServer
) -> None:
    data = tmp_path / "data"
    env = {**model.env(), "LTAA_LLM_GIVE_UP_AFTER": str(GIVE_UP_AFTER)}
    first = Server(data, env=env).start(pause=KILLED_AT)
    body = {"scenario": "baseline", "reasoner": "openai", "max_retries": MAX_RETRIES}
    created = first.client().post("/runs", json=body)
    assert created.status_code == 202, created.text
    run_id = created.json()["id"]
    first.wait_for_log(KILLED_AT.message(), timeout=600)
    assert model.requests().count(200) == 1  # task 0's first reply, recorded
    first.kill()

    second = Server(data, env=env).start()
    try:
        state: dict[str, Any] = second.wait_for(
            run_id, lambda s: s["status"] in ("completed", "failed"), timeout=1200
        )
        with second.client() as c:
            trace = c.get(f"/runs/{run_id}/trace", params={"include": "prompts"}).json()
            verified = c.get(f"/runs/{run_id}/trace/verify").json()
    finally:
        second.stop()

    assert state["status"] == "completed" and state["resumes"] == 1, state
    assert verified["ok"] is True and verified["decisions"] == 36
    decisions = trace["decisions"]
    assert [d["task_index"] for d in decisions] == list(range(36))
    asked = [a for d in decisions for a in d["attempts"] if a["reasoner"] == "openai"]
    answered = [a for a in asked if a["model"] is not None]
    assert decisions[0]["attempts"][0]["model"] is not None  # the reply recorded at the kill

    # Every stored decision is valid: an accepted answer that passed validation, or the
    # rules fallback after every attempt failed it. Structured: no reply unparseable.
    for d in decisions:
        accepted = [a for a in d["attempts"] if a["accepted"]]
        if d["fallback"]:
            assert not accepted and d["attempts"]
        else:
            [final] = accepted
            assert final["hard_invalid"] is None
            assert final["quality"] >= DEFAULT_QUALITY_THRESHOLD
    for a in answered:
        assert a["hard_invalid"] is None or "not complete JSON" not in a["hard_invalid"], a

    # The usage is what the server reported, attempt by attempt, and its prompt count is
    # the model's own tokenization of the prompt the trace holds.
    usage = state["usage"]
    assert usage["llm_calls"] == len(answered)
    assert usage["input_tokens"] == sum(a["input_tokens"] for a in answered)
    assert usage["output_tokens"] == sum(a["output_tokens"] for a in answered)
    tokenizer = Llama(model_path=str(model_file()), vocab_only=True, verbose=False)
    for a in answered[:3]:
        expected = _chat_tokens(tokenizer, a["system_prompt"], a["user_prompt"])
        assert a["input_tokens"] == expected, a["attempt"]
    assert all(0 < a["output_tokens"] <= 500 for a in answered)

    # The server's own log: one answered request per recorded model reply, so no decided
    # task was asked again after the kill; every 500 is its refusal of json_schema (each
    # process's first structured call, retried three times by the SDK).
    statuses = model.requests()
    assert statuses.count(200) == len(answered)
    assert statuses.count(500) == 2 * 4 and set(statuses) == {200, 500}
    # The model is asked until it fails two tasks in a row, then never again.
    gave_up = [e for e in trace["events"] if e["kind"] == "llm_gave_up"]
    assert len(gave_up) <= 1
    if gave_up:
        last_asked = max(
            d["task_index"] for d in decisions if d["attempts"][0]["reasoner"] == "openai"
        )
        assert gave_up[0]["detail"]["task_index"] == last_asked + 1
        assert gave_up[0]["detail"]["after"] == GIVE_UP_AFTER
