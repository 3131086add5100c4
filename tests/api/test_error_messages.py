"""Every 4xx message is a finished sentence: no template placeholder left unfilled.

The messages are collected by sending the bad inputs the bad-request tests send and reading
what comes back, rather than by scanning the templates in app/ statically. A static scan
cannot tell a filled template from an unfilled one without re-implementing each filler:
pydantic's `PydanticCustomError` fills `{name}` from its context, yet leaves `{limit:,}`
(a valid `str.format` field) and `{{` (a valid `str.format` escape) exactly as written, so a
scan that trusts "this template is formatted" passes the very bug it is meant to catch. What
the client reads is the only ground truth.
"""

from __future__ import annotations

import re
from typing import Any

from fastapi.testclient import TestClient

from tests.allocation import test_api_timed_bad_requests as timed
from tests.api import test_api_bad_requests as plain
from tests.api import test_hostile_input as hostile

# `{name}`, `{name!r}`, `{name:,}` or a `{{` escape: what str.format or pydantic would have
# filled. JSON examples in messages (`{"A": {"B": 6}}`, `{robot name: minutes}`) do not match.
PLACEHOLDER = re.compile(r"\{\{|\{[A-Za-z_]\w*(?:![rsa])?(?::[^{}\s]*)?\}")


def test_the_pattern_finds_the_placeholders_it_must_and_spares_json_examples() -> None:
    bad = [
        "a duration must be more than 0 and at most {limit:,} minutes, got -5",
        "a duration map names at least one robot: {{robot name: minutes}}",
        "task id must be at most {limit} characters",
        "got {got!r}",
    ]
    good = [
        'travel is a map of maps of minutes: {"A": {"B": 6}}',
        "a duration map names at least one robot: {robot name: minutes}",
        "a duration must be more than 0 and at most 10,000,000 minutes, got -5",
    ]
    assert [bool(PLACEHOLDER.search(m)) for m in bad + good] == [True] * 4 + [False] * 3


def _messages(response: Any) -> list[tuple[list[Any], str]]:
    assert 400 <= response.status_code < 500, response.text[:1000]
    return [(d["loc"], d["msg"]) for d in response.json()["detail"]]


def _sent(client: TestClient) -> list[tuple[list[Any], str]]:
    """(loc, msg) of every error the bad-request tests' inputs get back."""
    got: list[tuple[list[Any], str]] = []
    for _, body, *_ in plain.CASES:
        got += _messages(client.post("/allocate", json=body))
    for _, content, content_type, *_ in plain.RAW_CASES:
        headers = {"content-type": content_type}
        got += _messages(client.post("/allocate", content=content, headers=headers))
    for _, changes, *_ in timed.ALLOCATE_CASES:
        for solver in ("schedule", "greedy"):
            body = {**timed._body(changes), "solver": solver}
            got += _messages(client.post("/allocate", json=body))
    for _, tasks, robots, *_ in timed.RUN_CASES:
        body = {"tasks": tasks, "robots": robots, "reasoner": "rules"}
        got += _messages(client.post("/runs", json=body))
    for body in hostile.NUL_BODIES.values():
        got += _messages(client.post("/runs", json=body))
    for _, case in hostile.FREE_TEXT:
        got += _messages(case(client)[0])
    for method, path in hostile.RUN_PATHS:
        got += _messages(client.request(method, path.format("a%00b")))
    return got


def test_no_error_message_leaves_a_placeholder_unfilled(client: TestClient) -> None:
    got = _sent(client)
    # The scan covers the message that once read "at most {limit:,} minutes, got -5".
    duration = [msg for loc, msg in got if loc == ["body", "tasks", 1, "duration"]]
    assert any(msg.endswith("minutes, got -5") for msg in duration), duration
    assert len(got) > 100, len(got)
    unfilled = sorted({f"{loc}: {msg}" for loc, msg in got if PLACEHOLDER.search(msg)})
    assert not unfilled, "\n".join(unfilled)
    assert "a duration must be more than 0 and at most 10,000,000 minutes, got -5" in duration
