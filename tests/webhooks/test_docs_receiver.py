"""The webhook receiver example of docs/webhooks.md, run as written against signed messages."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.webhooks import signing
from app.webhooks.secret_box import new_secret

WEBHOOKS_DOC = Path(__file__).resolve().parents[2] / "docs" / "webhooks.md"


def receiver_source() -> str:
    blocks = re.findall(r"```python\n(.*?)```", WEBHOOKS_DOC.read_text(), flags=re.S)
    (source,) = [b for b in blocks if b.startswith("# receiver.py")]
    return source


def test_the_documented_receiver_verifies_and_deduplicates(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    secret = new_secret()
    monkeypatch.setenv("LTAA_WEBHOOK_SECRET", secret)
    namespace: dict[str, Any] = {}
    exec(compile(receiver_source(), "docs/webhooks.md:receiver.py", "exec"), namespace)
    body = json.dumps(
        {
            "type": "run.completed",
            "timestamp": "2026-12-01T20:00:00.000Z",
            "data": {"run_id": "r1", "status": "completed", "expected_success": 0.84},
        }
    ).encode()
    headers = signing.headers([secret], "msg_1", int(time.time()), body)
    with TestClient(namespace["app"]) as client:
        assert client.post("/ltaa-hooks", content=body, headers=headers).status_code == 204
        assert client.post("/ltaa-hooks", content=body, headers=headers).status_code == 204
        forged = signing.headers([new_secret()], "msg_2", int(time.time()), body)
        assert client.post("/ltaa-hooks", content=body, headers=forged).status_code == 400
    assert capsys.readouterr().out.count("run r1 done, ES 0.84") == 1  # the retry is skipped
