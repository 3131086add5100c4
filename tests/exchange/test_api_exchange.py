"""POST /schedules/import and GET /runs/{id}/schedule?format=mspdi over HTTP: files MPXJ
wrote import to the draft app.exchange reads, hostile and wrong files are 4xx naming the
problem and the server keeps serving, and a run's plan exports as MSPDI that MPXJ reads
with the plan's dates (docs/exchange.md)."""

from __future__ import annotations

from datetime import datetime

import pytest
from fastapi.testclient import TestClient
from pydantic import SecretStr

from app.exchange import read_mspdi, read_xer
from tests.support.clients import ClientFactory
from tests.support.exchange_support import files
from tests.support.mpxj_oracle import read, to_datetime
from tests.support.polling import wait_until

pytestmark = pytest.mark.usefixtures("mpxj")


def test_mspdi_and_xer_import_to_the_draft_the_readers_give(client: TestClient) -> None:
    mspdi = client.post(
        "/schedules/import",
        content=files()["mspdi"],
        params={"features_field": "Text1"},
        headers={"Content-Type": "application/xml"},
    )
    assert mspdi.status_code == 200, mspdi.text
    assert mspdi.json() == read_mspdi(files()["mspdi"], features_field="Text1").to_dict()
    xer = client.post("/schedules/import", content=files()["xer"], params={"format": "xer"})
    assert xer.status_code == 200, xer.text
    assert xer.json() == read_xer(files()["xer"]).to_dict()
    body = {k: mspdi.json()[k] for k in ("tasks", "robots", "start")}
    assert body == {k: xer.json()[k] for k in ("tasks", "robots", "start")}
    defaults = client.post(
        "/schedules/import", content=files()["xer"], params={"default_features": "clean,sweep"}
    )
    assert {t["name"]: t["features"] for t in defaults.json()["tasks"]}["Sweep"] == [
        "clean",
        "sweep",
    ]


def test_hostile_and_wrong_files_are_422s_and_the_server_keeps_serving(
    client: TestClient,
) -> None:
    laughs = (
        '<?xml version="1.0"?><!DOCTYPE P [<!ENTITY a "aaaaaaaaaa">'
        + "".join(f'<!ENTITY a{i} "{"&a;" * 10}">' for i in range(10))
        + ']><Project xmlns="http://schemas.microsoft.com/project"><Name>&a9;</Name></Project>'
    )
    refused = client.post("/schedules/import", content=laughs)
    assert refused.status_code == 422
    (detail,) = refused.json()["detail"]
    assert detail["type"] == "unsafe_xml" and detail["loc"] == ["body"]
    wrong = client.post("/schedules/import", content=b'{"tasks": []}')
    assert wrong.status_code == 422
    assert "expected an MSPDI file" in wrong.json()["detail"][0]["msg"]
    assert "found JSON" in wrong.json()["detail"][0]["msg"]
    named = client.post("/schedules/import", content=files()["mspdi"], params={"format": "xer"})
    assert named.status_code == 422 and "found XML" in named.json()["detail"][0]["msg"]
    field = client.post(
        "/schedules/import", content=files()["mspdi"], params={"features_field": "Colour"}
    )
    assert field.status_code == 422
    assert field.json()["detail"][0]["loc"] == ["query", "features_field"]
    bad_format = client.post("/schedules/import", content=b"x", params={"format": "mpp"})
    assert bad_format.status_code == 422
    assert client.get("/health").status_code == 200


def test_a_file_over_the_import_limit_is_a_413_the_import_limit_names(
    make_client: ClientFactory,
) -> None:
    size = len(files()["mspdi"])
    client = make_client(max_body_bytes=1000, import_max_bytes=size)
    assert client.post("/schedules/import", content=files()["mspdi"]).status_code == 200
    over = client.post("/schedules/import", content=files()["mspdi"] + b" ")
    assert over.status_code == 413
    assert "LTAA_IMPORT_MAX_BYTES" in over.json()["detail"][0]["msg"]
    # Elsewhere the request limit holds as before.
    other = client.post("/allocate", content=b"[" + b" " * 2000 + b"]")
    assert other.status_code == 413 and "LTAA_MAX_BODY_BYTES" in other.text


def test_the_import_needs_a_client_key(make_client: ClientFactory) -> None:
    keys = SecretStr("client-key-000001:client,super-key-0000001:supervisor")
    client = make_client(api_keys=keys)
    assert client.post("/schedules/import", content=files()["xer"]).status_code == 401
    ok = client.post(
        "/schedules/import", content=files()["xer"], headers={"X-API-Key": "client-key-000001"}
    )
    assert ok.status_code == 200, ok.text


def test_a_runs_plan_exports_as_mspdi_that_mpxj_reads_with_its_dates(client: TestClient) -> None:
    created = client.post("/runs", json={"scenario": "baseline_timed"})
    assert created.status_code == 202, created.text
    run_id = created.json()["id"]
    assert wait_until(client, run_id, timeout=120)["status"] == "completed"
    plan = client.get(f"/runs/{run_id}/schedule").json()
    exported = client.get(f"/runs/{run_id}/schedule", params={"format": "mspdi"})
    assert exported.status_code == 200, exported.text
    assert exported.headers["content-type"].startswith("application/vnd.ms-project+xml")
    project = read(exported.content)
    by_id = {str(t.getText(2)): t for t in project.getTasks() if t.getName() is not None}
    rows = plan["tasks"]
    assert len(by_id) == len(rows) == 36
    for row in rows:
        task = by_id[str(row["task_id"])]
        start = datetime.fromisoformat(row["start_at"])
        assert to_datetime(task.getStart()) == start.replace(tzinfo=None)
        names = [str(a.getResource().getName()) for a in task.getResourceAssignments()]
        assert names == [row["robot"]]
    draft = client.post("/schedules/import", content=exported.content).json()
    assert len(draft["tasks"]) == 36 and draft["skipped"] == []
