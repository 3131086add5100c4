"""The console's import forms through the in-process client: the CSRF token is required,
a tampered or unplannable draft is a 4xx page naming the problem with no run written, and
a file over LTAA_IMPORT_MAX_BYTES is a 413 (the browser tests drive the page itself)."""

from __future__ import annotations

import json
import re
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.exchange import read_mspdi
from tests.support.clients import ClientFactory
from tests.support.exchange_files import small_mspdi

TOKEN = re.compile(r'name="csrf_token" value="([^"]+)"')


def _token(client: TestClient) -> str:
    found = TOKEN.search(client.get("/console/import").text)
    assert found
    return found[1]


def _upload(client: TestClient, data: bytes, **form: str) -> Any:
    return client.post(
        "/console/import",
        data=form,
        files={"file": ("plan.xml", data, "application/xml")},
        follow_redirects=False,
    )


def test_the_forms_need_the_sessions_token(client: TestClient) -> None:
    refused = _upload(client, small_mspdi(), csrf_token="guess")
    assert refused.status_code == 403
    draft = json.dumps(read_mspdi(small_mspdi()).request())
    start = client.post("/console/import/run", data={"draft": draft}, follow_redirects=False)
    assert start.status_code == 403
    assert client.get("/runs").json() == []


@pytest.mark.parametrize(
    ("draft", "words"),
    [
        ("not json", "draft: it is not a run request"),
        (json.dumps({"tasks": [{"id": "1"}], "robots": []}), "draft: it is not a run request"),
        # No robot rates the features: what the page says before it offers a start.
        (json.dumps(read_mspdi(small_mspdi()).request()), "rate at least one feature"),
    ],
)
def test_a_tampered_or_unplannable_draft_starts_nothing(
    client: TestClient, draft: str, words: str
) -> None:
    answer = client.post(
        "/console/import/run",
        data={"csrf_token": _token(client), "draft": draft},
        follow_redirects=False,
    )
    assert answer.status_code == 422, answer.text
    assert "Run not started" in answer.text and words in answer.text
    assert client.get("/runs").json() == []


def test_an_unknown_site_and_an_oversized_file_are_refused(make_client: ClientFactory) -> None:
    limit = len(small_mspdi()) + 1000  # the file and the form's other parts fit
    client = make_client(import_max_bytes=limit)
    token = _token(client)
    missing = _upload(client, small_mspdi(), csrf_token=token, site="nowhere")
    assert missing.status_code == 404 and "GET /sites" in missing.text
    big = _upload(client, small_mspdi() + b" " * limit, csrf_token=token)
    assert big.status_code == 413 and "LTAA_IMPORT_MAX_BYTES" in big.text
