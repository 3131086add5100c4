"""A fake Anthropic Messages API on 127.0.0.1, for driving the real SDK without the network.

Serves POST /v1/messages from a scripted queue of replies (answers, HTTP errors in the
API's error shape with `retry-after`, delayed replies that trip the client timeout, and
broken bodies: empty, cut off, not JSON, or a connection dropped mid-body); when the queue
is empty it
falls back to a default responder (by default: a good answer computed from the prompt, so
end-to-end runs of any length work unscripted). Every request and every delivered reply
is recorded, with the token counts it reported.

    with FakeMessagesAPI() as api:
        api.script(Reply.error(429), Reply.answer("**Decision**: ..."))
        client = anthropic.Anthropic(api_key="test", base_url=api.base_url)

Run standalone for manual or subprocess use:  python -m tests.fakes.fake_messages_api --port 0
"""

from __future__ import annotations

import argparse
import itertools
import json
import re
import select
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Self

from app.domain.decision import DecisionContext, Members, TeamFacts
from app.domain.modes import Mode, strategic_weights
from app.domain.phases import Phase
from app.reasoners.rules import compose_answer
from tests.fakes.structured_replies import as_structured, asked_schema

Responder = Callable[[dict[str, Any]], "Reply"]

_ERROR_TYPES = {
    400: "invalid_request_error",
    401: "authentication_error",
    404: "not_found_error",
    429: "rate_limit_error",
    500: "api_error",
    529: "overloaded_error",
}


def estimate_tokens(text: str) -> int:
    return max(1, len(text) // 4)


@dataclass
class Reply:
    """One scripted response. `text=None` with status 200 means "answer from the prompt"."""

    status: int = 200
    text: str | None = None
    headers: dict[str, str] = field(default_factory=dict)
    delay_s: float = 0.0
    input_tokens: int | None = None  # default: estimated from the request
    output_tokens: int | None = None  # default: estimated from the text
    # Broken bodies (status 200 unless set): `body` is sent verbatim instead of a message;
    # `cut_to` keeps only the first bytes of the message JSON (Content-Length matching, as
    # a proxy that truncates); `drop_after` announces the full length, sends that many
    # bytes and closes the connection (the client sees an incomplete body).
    body: bytes | None = None
    content_type: str = "application/json"
    cut_to: int | None = None
    drop_after: int | None = None

    @property
    def wellformed(self) -> bool:
        return self.body is None and self.cut_to is None and self.drop_after is None

    @classmethod
    def answer(cls, text: str, **kw: Any) -> Reply:
        return cls(text=text, **kw)

    @classmethod
    def from_prompt(cls, **kw: Any) -> Reply:
        """A good answer computed from the prompt (see answer_from_prompt)."""
        return cls(text=None, **kw)

    @classmethod
    def error(cls, status: int = 429, *, retry_after: float | None = 0.05) -> Reply:
        headers = {} if retry_after is None else {"retry-after": f"{retry_after:g}"}
        return cls(status=status, headers=headers)

    @classmethod
    def slow(cls, delay_s: float, text: str | None = None) -> Reply:
        """Answers only after `delay_s`: longer than the client's timeout, it is a timeout."""
        return cls(text=text, delay_s=delay_s)

    @classmethod
    def overloaded(cls, *, retry_after: float | None = 0.05) -> Reply:
        """529 `overloaded_error`, the API's answer when it is short of capacity."""
        reply = cls.error(529, retry_after=retry_after)
        reply.text = "Overloaded"
        return reply

    @classmethod
    def empty(cls) -> Reply:
        """200 with an empty body."""
        return cls(body=b"")

    @classmethod
    def truncated(cls, keep: int = 60) -> Reply:
        """200 whose message JSON stops after `keep` bytes."""
        return cls(cut_to=keep)

    @classmethod
    def garbage(cls) -> Reply:
        """200 with an HTML page, as a misbehaving proxy in front of the API sends."""
        return cls(body=b"<html><body>upstream says hello</body></html>", content_type="text/html")

    @classmethod
    def dropped(cls, after: int = 40) -> Reply:
        """200 whose connection closes after `after` bytes of the announced body."""
        return cls(drop_after=after)


@dataclass
class Served:
    status: int
    input_tokens: int = 0
    output_tokens: int = 0
    delivered: bool = True  # False when the client had gone (e.g. it timed out first)
    wellformed: bool = True  # False for a broken body (empty, cut off, not JSON, dropped)


# ---------------------------------------------------------------- prompt -> good answer

_TASK = re.compile(r"^Task (\d+)/(\d+): (.*?)(?: \(([^()]*)\))?; features: (.+)$", re.M)
_ROBOT = re.compile(
    r"^- (.+?) \[([^\]]+)\]: S ([\d.]+)%(?: \([^)]*\))?, load (\d+) \(dev [^)]*\)(, NOT allowed)?"
    r"(?:, cannot take this task)?$",
    re.M,
)
_TARGET = re.compile(
    r"^Target load W = ([\d.]+)(?: \([^)]*\))?;.*?(?:final loads in \[(\d+), (\d+)\])?", re.M
)
_PHASE = re.compile(r"^Phase: (early|middle|late)\b|the (early|middle|late) phase of", re.M)
_MODE = re.compile(r"^Mode: (\w+),|phase of (\w+) mode", re.M)
_GUIDED = re.compile(r"^Optimizer guidance: (.+?) lies on", re.M)
# docs/allocation.md#teams: a team task's prompt (app.graph.team_prompts).
# A timed team prompt adds each robot's time after `; ` and each candidate's after `, in time`.
_TEAM_ROBOT = re.compile(
    r"^- (.+?) \[([^\]]+)\]: load (\d+) \(dev [^)]*\)(, NOT allowed)?(?:; .*)?$", re.M
)
_UNIT = re.compile(r"^- (\S+) x(\d+): (.*)$", re.M)
_CANDIDATE = re.compile(
    r"^- (best|least-loaded): (.+) \(S [\d.]+%, loads \d+\)(?:, in time .*)?$", re.M
)
_GUIDED_TEAM = re.compile(r"^Optimizer guidance: the team (.+?) lies on", re.M)


def _members(text: str, facts: TeamFacts, labels: tuple[str, ...]) -> Members:
    """`heavy: Crane, Lifter; careful: Arm` -> the members in unit order."""
    named = dict(part.split(": ", 1) for part in text.split("; "))
    return tuple(labels.index(x) for f in facts.features for x in named[f].split(", "))


def _team_context(prompt: str, base: dict[str, Any]) -> DecisionContext:
    robots = _TEAM_ROBOT.findall(prompt)
    labels = tuple(r[0] for r in robots)
    units: list[str] = []
    rates: list[tuple[float | None, ...]] = []
    for feature, count, who in _UNIT.findall(prompt):
        units += [feature] * int(count)
        rate = {m[1]: float(m[2]) / 100 for m in re.finditer(r"(.+?) ([\d.]+)%(?:, |$)", who)}
        rates.append(tuple(rate.get(label) for label in labels))
    facts = TeamFacts(units=tuple(units), rates=tuple(rates))
    found = dict(_CANDIDATE.findall(prompt))
    guided = _GUIDED_TEAM.search(prompt)
    facts = TeamFacts(
        units=facts.units,
        rates=facts.rates,
        best=_members(found["best"], facts, labels),
        fewest=_members(found["least-loaded"], facts, labels),
        guided=_members(guided.group(1), facts, labels) if guided else None,
    )
    return DecisionContext(
        **base,
        robot_names=tuple(r[1] for r in robots),
        robot_labels=labels,
        success=(0.0,) * len(robots),
        loads=tuple(int(r[2]) for r in robots),
        feasible=tuple(i for i, r in enumerate(robots) if not r[3]),
        team=facts,
    )


def context_from_prompt(prompt: str) -> DecisionContext:
    """Rebuild the decision facts from a prompt written by app.graph.prompts (any tier)."""
    task = _TASK.search(prompt)
    robots = _ROBOT.findall(prompt)
    target = _TARGET.search(prompt)
    phase_m, mode_m = _PHASE.search(prompt), _MODE.search(prompt)
    team = "\nTeam task: " in prompt
    if not (task and (robots or team) and target and phase_m and mode_m):
        raise ValueError("not an LTAA decision prompt")
    phase = Phase(phase_m.group(1) or phase_m.group(2))
    mode = Mode(mode_m.group(1) or mode_m.group(2))
    if team:
        return _team_context(
            prompt,
            {
                "task_index": int(task.group(1)) - 1,
                "total_tasks": int(task.group(2)),
                "task_name": task.group(3),
                "task_type": task.group(4) or "",
                "features": tuple(f.strip() for f in task.group(5).split(",")),
                "target": float(target.group(1)),
                "phase": phase,
                "mode": mode,
                "weights": strategic_weights(mode, phase),
            },
        )
    labels = tuple(r[0] for r in robots)
    guided = _GUIDED.search(prompt)
    return DecisionContext(
        task_index=int(task.group(1)) - 1,
        total_tasks=int(task.group(2)),
        task_name=task.group(3),
        task_type=task.group(4) or "",
        features=tuple(f.strip() for f in task.group(5).split(",")),
        robot_names=tuple(r[1] for r in robots),
        robot_labels=labels,
        success=tuple(float(r[2]) / 100 for r in robots),
        loads=tuple(int(r[3]) for r in robots),
        target=float(target.group(1)),
        feasible=tuple(i for i, r in enumerate(robots) if not r[4]),
        phase=phase,
        mode=mode,
        weights=strategic_weights(mode, phase),
        guided_robot=labels.index(guided.group(1)) if guided else None,
    )


def answer_from_prompt(prompt: str) -> str:
    """The answer the rules reasoner would give to the decision this prompt describes."""
    return compose_answer(context_from_prompt(prompt))


def prompt_of(request: dict[str, Any]) -> str:
    content = request["messages"][-1]["content"]
    if isinstance(content, str):
        return content
    return "".join(block.get("text", "") for block in content)


def good_responder(request: dict[str, Any]) -> Reply:
    return Reply.answer(answer_from_prompt(prompt_of(request)))


# ------------------------------------------------------------------------------ server


class FakeMessagesAPI:
    """The Messages API; subclasses speak another provider's dialect (see _error_body,
    _message_body, _usage_of) over the same scripting, faults and accounting."""

    PATH = "/v1/messages"
    NAME = "fake Messages API"

    def __init__(self, *, default: Responder | None = good_responder, port: int = 0) -> None:
        self._queue: deque[Reply | Responder] = deque()
        self._default = default
        self._lock = threading.Lock()
        self._ids = itertools.count(1)
        self.requests: list[dict[str, Any]] = []  # bodies, plus "_headers", "_received_at"
        self.served: list[Served] = []
        self._server = ThreadingHTTPServer(("127.0.0.1", port), self._handler_class())
        self._server.daemon_threads = True
        self._thread: threading.Thread | None = None

    # -- script
    def script(self, *replies: Reply | Responder) -> None:
        with self._lock:
            self._queue.extend(replies)

    def pending(self) -> int:
        with self._lock:
            return len(self._queue)

    # -- accounting
    def tokens(self) -> tuple[int, int]:
        """(input, output) tokens reported by delivered, readable 200 replies."""
        ok = [s for s in self.served if s.status == 200 and s.delivered and s.wellformed]
        return sum(s.input_tokens for s in ok), sum(s.output_tokens for s in ok)

    def answered(self) -> int:
        return sum(1 for s in self.served if s.status == 200 and s.delivered and s.wellformed)

    # -- lifecycle
    @property
    def base_url(self) -> str:
        host, port = self._server.server_address[:2]
        assert isinstance(host, str)  # an AF_INET server's host is text (AF_UNIX's is bytes)
        return f"http://{host}:{port}"

    def start(self) -> Self:
        self._thread = threading.Thread(
            target=self._server.serve_forever, daemon=True, name=self.NAME.replace(" ", "-")
        )
        self._thread.start()
        return self

    def stop(self) -> None:
        self._server.shutdown()
        self._server.server_close()
        if self._thread is not None:
            self._thread.join(timeout=5)

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- request handling
    def _next(self, request: dict[str, Any]) -> Reply:
        with self._lock:
            item = self._queue.popleft() if self._queue else None
        if item is None:
            if self._default is None:
                return Reply(
                    status=500,
                    headers={"x-should-retry": "false"},
                    text=f"{self.NAME}: script exhausted",
                )
            return self._default(request)
        return item(request) if callable(item) else item

    def _respond(self, request: dict[str, Any]) -> tuple[Reply, int, dict[str, Any]]:
        reply = self._next(request)
        if reply.status != 200:
            return reply, reply.status, self._error_body(reply.status, reply.text)
        if reply.body is not None:
            return reply, reply.status, {}  # sent verbatim: no message to compose
        text = reply.text if reply.text is not None else answer_from_prompt(prompt_of(request))
        schema = asked_schema(request)
        if schema is not None:  # docs/reasoners.md#structured-replies: as a constrained server
            text = as_structured(text, schema)
        prompt = self._system_of(request) + prompt_of(request)
        in_tokens = (
            reply.input_tokens if reply.input_tokens is not None else estimate_tokens(prompt)
        )
        out_tokens = (
            reply.output_tokens if reply.output_tokens is not None else estimate_tokens(text)
        )
        return reply, 200, self._message_body(request, text, in_tokens, out_tokens)

    # -- the dialect
    def _error_body(self, status: int, message: str | None) -> dict[str, Any]:
        return {
            "type": "error",
            "error": {
                "type": _ERROR_TYPES.get(status, "api_error"),
                "message": message or f"fake {status}",
            },
            "request_id": f"req_fake_{next(self._ids):05d}",
        }

    def _system_of(self, request: dict[str, Any]) -> str:
        return str(request.get("system") or "")

    def _message_body(
        self, request: dict[str, Any], text: str, in_tokens: int, out_tokens: int
    ) -> dict[str, Any]:
        content: dict[str, Any] = {"type": "text", "text": text}
        tool = (request.get("tool_choice") or {}).get("name")
        if tool is not None:
            # Forced tool use: the structured reply is the tool's input (a JSON object; a
            # scripted reply that is no object comes back as text, as a model's words).
            try:
                value = json.loads(text)
            except json.JSONDecodeError:
                value = None
            if isinstance(value, dict):
                content = {"type": "tool_use", "id": "toolu_fake", "name": tool, "input": value}
        return {
            "id": f"msg_fake_{next(self._ids):05d}",
            "type": "message",
            "role": "assistant",
            "model": request.get("model", "fake-model"),
            "content": [content],
            "stop_reason": "tool_use" if content["type"] == "tool_use" else "end_turn",
            "stop_sequence": None,
            "usage": {"input_tokens": in_tokens, "output_tokens": out_tokens},
        }

    def _usage_of(self, body: dict[str, Any]) -> tuple[int, int]:
        usage = body.get("usage", {})
        return usage.get("input_tokens", 0), usage.get("output_tokens", 0)

    def _handler_class(self) -> type[BaseHTTPRequestHandler]:
        api = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, format: str, *args: Any) -> None:  # quiet test output
                return

            def do_POST(self) -> None:
                length = int(self.headers.get("content-length") or 0)
                raw = self.rfile.read(length)
                if self.path.split("?")[0] != api.PATH:
                    self._send(404, api._error_body(404, self.path), Reply(status=404))
                    return
                request = json.loads(raw or b"{}")
                request["_headers"] = {k.lower(): v for k, v in self.headers.items()}
                request["_received_at"] = time.monotonic()
                with api._lock:
                    api.requests.append(request)
                reply, status, body = api._respond(request)
                if reply.delay_s:
                    time.sleep(reply.delay_s)
                delivered = not self._peer_closed() and self._send(status, body, reply)
                # A broken body reports no usage the client could read.
                in_tokens, out_tokens = api._usage_of(body) if reply.wellformed else (0, 0)
                with api._lock:
                    api.served.append(
                        Served(status, in_tokens, out_tokens, delivered, reply.wellformed)
                    )

            def _peer_closed(self) -> bool:
                # A client that timed out has closed its end: the reply would go nowhere.
                readable, _, _ = select.select([self.connection], [], [], 0)
                if not readable:
                    return False
                try:
                    return self.connection.recv(1, socket.MSG_PEEK) == b""
                except OSError:
                    return True

            def _send(self, status: int, body: dict[str, Any], reply: Reply) -> bool:
                data = json.dumps(body).encode() if reply.body is None else reply.body
                if reply.cut_to is not None:
                    data = data[: reply.cut_to]
                length = len(data)
                if reply.drop_after is not None:
                    data = data[: reply.drop_after]
                try:
                    self.send_response(status)
                    self.send_header("content-type", reply.content_type)
                    self.send_header("content-length", str(length))
                    self.send_header("request-id", f"req_fake_{time.monotonic_ns()}")
                    for k, v in reply.headers.items():
                        self.send_header(k, v)
                    self.end_headers()
                    self.wfile.write(data)
                    self.wfile.flush()
                except (BrokenPipeError, ConnectionResetError):
                    return False
                if reply.drop_after is not None:
                    self.close_connection = True
                    self.connection.shutdown(socket.SHUT_RDWR)
                return True

        return Handler


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--port", type=int, default=0)
    args = parser.parse_args()
    api = FakeMessagesAPI(port=args.port).start()
    print(api.base_url, flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        api.stop()


if __name__ == "__main__":
    main()
