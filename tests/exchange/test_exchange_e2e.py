"""Schedule files on a real uvicorn server (docs/exchange.md#bad-files): an XXE file, a
"billion laughs" file and bodies over LTAA_IMPORT_MAX_BYTES (declared and chunked) are
refused as the docs say, nothing read from the server's disk is echoed, and /health
answers after each; then a file imports with a site's rates, runs, and exports as MSPDI
that imports back; `ltaa import --site` reads the same rates from the server."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from typer.testing import CliRunner

from app.cli import cli
from app.exchange import read_mspdi
from tests.support.exchange_files import small_mspdi
from tests.support.server import Server

pytestmark = pytest.mark.e2e

LIMIT = 64_000
SECRET = "ltaa-e2e-secret-7f3a9c"
NS = 'xmlns="http://schemas.microsoft.com/project"'


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    srv = Server(tmp_path_factory.mktemp("exchange"), env={"LTAA_IMPORT_MAX_BYTES": str(LIMIT)})
    srv.start()
    yield srv
    srv.stop()


def _healthy(c: httpx.Client) -> None:
    assert c.get("/health").status_code == 200


def _refused(answer: httpx.Response, status: int, kind: str) -> dict[str, Any]:
    assert answer.status_code == status, answer.text
    (item,) = answer.json()["detail"]
    assert item["type"] == kind, item
    return dict(item)


def test_hostile_files_are_refused_and_the_server_keeps_serving(
    server: Server, tmp_path: Path
) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text(SECRET)
    xxe = (
        f'<?xml version="1.0"?><!DOCTYPE Project [<!ENTITY s SYSTEM "file://{secret}">]>'
        f"<Project {NS}><Name>&s;</Name><Tasks/></Project>"
    )
    laughs = (
        '<?xml version="1.0"?><!DOCTYPE P [<!ENTITY a0 "ha">'
        + "".join(f'<!ENTITY a{i} "{f"&a{i - 1};" * 10}">' for i in range(1, 10))
        + f"]><Project {NS}><Name>&a9;</Name></Project>"
    )
    big = small_mspdi() + b"<!-- " + b"x" * LIMIT + b" -->"

    def chunks() -> Iterator[bytes]:
        for start in range(0, len(big), 4096):
            yield big[start : start + 4096]

    with server.client() as c:
        runs_before = c.get("/runs").json()
        answer = c.post("/schedules/import", content=xxe)
        item = _refused(answer, 422, "unsafe_xml")
        assert SECRET not in answer.text and item["loc"] == ["body"]
        _healthy(c)

        began = time.monotonic()
        answer = c.post("/schedules/import", content=laughs)
        _refused(answer, 422, "unsafe_xml")
        assert time.monotonic() - began < 1.0
        _healthy(c)

        for content in (big, chunks()):
            answer = c.post("/schedules/import", content=content)
            item = _refused(answer, 413, "body_too_large")
            assert "LTAA_IMPORT_MAX_BYTES" in item["msg"] and f"{LIMIT:,}" in item["msg"]
            _healthy(c)
        assert c.get("/runs").json() == runs_before  # nothing stored


def test_a_file_imports_with_site_rates_runs_and_exports_back(server: Server) -> None:
    with server.client() as c:
        seeded = c.post("/runs", json={"scenario": "baseline", "reasoner": "rules", "site": "e2e"})
        assert seeded.status_code == 202, seeded.text
        server.wait_for(seeded.json()["id"], lambda s: s["status"] == "completed")
        answer = c.post(
            "/schedules/import", params={"site": "e2e"}, content=small_mspdi(typed=True)
        )
        assert answer.status_code == 200, answer.text
        draft = answer.json()
        assert all(r["success"] for r in draft["robots"])
        assert c.post("/schedules/import", params={"site": "nowhere"}, content=small_mspdi()
                      ).status_code == 404  # fmt: skip
        assert draft["tasks"][1]["after"] == [{"task": "1", "type": "SS", "lag": 20}]
        local = read_mspdi(small_mspdi(typed=True))
        local.robots[:] = draft["robots"]
        created = c.post("/runs", json={**local.request(), "site": "e2e"})
        assert created.status_code == 202, created.text
        run_id = created.json()["id"]
        server.wait_for(run_id, lambda s: s["status"] == "completed")
        # The durable run honours the start-to-start link (docs/schedules.md#links).
        planned = {str(a["task_id"]): a for a in c.get(f"/runs/{run_id}").json()["assignments"]}
        assert planned["2"]["start"] >= planned["1"]["start"] + 20 - 1e-6
        exported = c.get(f"/runs/{run_id}/schedule", params={"format": "mspdi"})
        assert exported.status_code == 200
        assert exported.headers["content-type"].startswith("application/vnd.ms-project+xml")
        back = c.post("/schedules/import", content=exported.content).json()
    # The command line prints the same file for the run's id, read from the server.
    printed = CliRunner().invoke(
        cli, ["schedule", run_id, "--format", "mspdi", "--url", server.url]
    )
    assert printed.exit_code == 0, printed.output
    assert printed.stdout == exported.text
    unknown = CliRunner().invoke(
        cli, ["schedule", "no-such-run", "--format", "mspdi", "--url", server.url]
    )
    said = " ".join(unknown.output.split())  # rich wraps the line on the terminal's width
    assert unknown.exit_code == 1 and "no schedule for a run of that id (404" in said
    assert [(t["id"], t["duration"], t["features"]) for t in back["tasks"]] == [
        (t["id"], t["duration"], t["features"]) for t in draft["tasks"]
    ]
    assert [t["after"] for t in back["tasks"]] == [t["after"] for t in draft["tasks"]]


def test_the_cli_reads_a_sites_rates_from_the_server(server: Server, tmp_path: Path) -> None:
    path = tmp_path / "fit-out.xml"
    path.write_bytes(small_mspdi())
    with server.client() as c:
        seeded = c.post("/runs", json={"scenario": "baseline", "reasoner": "rules", "site": "cli"})
        server.wait_for(seeded.json()["id"], lambda s: s["status"] == "completed")
        api = c.post("/schedules/import", params={"site": "cli"}, content=small_mspdi()).json()
    runner = CliRunner()
    result = runner.invoke(cli, ["import", str(path), "--site", "cli", "--url", server.url])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout) == api
    missing = runner.invoke(cli, ["import", str(path), "--site", "elsewhere", "--url", server.url])
    assert missing.exit_code == 1 and "404" in missing.output
