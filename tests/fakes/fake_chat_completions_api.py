"""A fake OpenAI-compatible Chat Completions server on 127.0.0.1 (as vLLM, Ollama or
llama.cpp serve it), for driving the real `openai` SDK without the network.

The same scripting, fault injection (HTTP errors with `retry-after`, delays that trip the
client timeout, empty / cut-off / HTML bodies, connections dropped mid-body) and call log
as the fake Messages API (tests.fakes.fake_messages_api), in the Chat Completions dialect:
POST /v1/chat/completions, `choices[0].message.content`, `usage.prompt_tokens` /
`usage.completion_tokens`, and errors as `{"error": {"message", "type", "code"}}`.

    with FakeChatCompletionsAPI() as api:
        api.script(Reply.error(429), Reply.answer("**Decision**: ..."))
        client = openai.OpenAI(api_key="test", base_url=api.base_url)  # ends in /v1

Run standalone:  python -m tests.fakes.fake_chat_completions_api --port 0
"""

from __future__ import annotations

import argparse
import itertools
import time
from typing import Any

from tests.fakes.fake_messages_api import (
    FakeMessagesAPI,
    Reply,
    Responder,
    Served,
    good_responder,
)

__all__ = ["FakeChatCompletionsAPI", "Reply", "Served", "good_responder"]

# What llama-cpp-python 0.3.36's server answers `response_format: {"type": "json_schema"}`
# with (HTTP 500), measured against the real server.
LLAMA_CPP_REFUSAL = (
    "1 validation error:\n  {'type': 'literal_error', 'loc': ('body', 'response_format', "
    "'type'), 'msg': \"Input should be 'text' or 'json_object'\", 'input': 'json_schema'}"
)

_ERROR_TYPES = {
    400: "invalid_request_error",
    401: "invalid_request_error",
    404: "invalid_request_error",
    429: "rate_limit_exceeded",
}


class FakeChatCompletionsAPI(FakeMessagesAPI):
    PATH = "/v1/chat/completions"
    NAME = "fake Chat Completions API"

    def __init__(self, *, refuse_json_schema: bool = False, **kw: Any) -> None:
        """`refuse_json_schema`: answer `response_format: json_schema` as llama-cpp-python's
        server does (HTTP 500 naming the field), so only json_object + schema is taken."""
        super().__init__(**kw)
        self.refuse_json_schema = refuse_json_schema

    def _respond(self, request: dict[str, Any]) -> tuple[Reply, int, dict[str, Any]]:
        fmt = request.get("response_format") or {}
        if self.refuse_json_schema and fmt.get("type") == "json_schema":
            reply = Reply.error(500, retry_after=None)
            return reply, 500, self._error_body(500, LLAMA_CPP_REFUSAL)
        return super()._respond(request)

    @property
    def base_url(self) -> str:
        """What LTAA_OPENAI_BASE_URL is set to: OpenAI-compatible servers root at /v1."""
        return super().base_url + "/v1"

    def _error_body(self, status: int, message: str | None) -> dict[str, Any]:
        return {
            "error": {
                "message": message or f"fake {status}",
                "type": _ERROR_TYPES.get(status, "server_error"),
                "param": None,
                "code": None,
            }
        }

    def _system_of(self, request: dict[str, Any]) -> str:
        return "".join(
            str(m.get("content") or "")
            for m in request.get("messages", [])
            if m.get("role") == "system"
        )

    def _message_body(
        self, request: dict[str, Any], text: str, in_tokens: int, out_tokens: int
    ) -> dict[str, Any]:
        return {
            "id": f"chatcmpl-fake{next(self._ids):05d}",
            "object": "chat.completion",
            "created": int(time.time()),
            "model": request.get("model", "fake-model"),
            "choices": [
                {
                    "index": 0,
                    "message": {"role": "assistant", "content": text},
                    "finish_reason": "stop",
                    "logprobs": None,
                }
            ],
            "usage": {
                "prompt_tokens": in_tokens,
                "completion_tokens": out_tokens,
                "total_tokens": in_tokens + out_tokens,
            },
        }

    def _usage_of(self, body: dict[str, Any]) -> tuple[int, int]:
        usage = body.get("usage", {})
        return usage.get("prompt_tokens", 0), usage.get("completion_tokens", 0)


def unusable_every(n: int) -> Responder:
    """Good answers, but every n-th reply an unusable one (a validation retry follows)."""
    from tests.fakes.scripted_reasoner import GARBAGE

    count = itertools.count(1)

    def respond(request: dict[str, Any]) -> Reply:
        return Reply.answer(GARBAGE) if next(count) % n == 0 else good_responder(request)

    return respond


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--port", type=int, default=0)
    parser.add_argument(
        "--unusable-every", type=int, default=0, help="every N-th reply is unusable (0: none)"
    )
    args = parser.parse_args()
    default = unusable_every(args.unusable_every) if args.unusable_every else good_responder
    api = FakeChatCompletionsAPI(port=args.port, default=default).start()
    print(api.base_url, flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        api.stop()


if __name__ == "__main__":
    main()
