"""The offline chain check of docs/audit.md, run as written against a real export."""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

from fastapi.testclient import TestClient

from tests.support.offline_check import check_offline
from tests.support.polling import eventually

ROOT = Path(__file__).resolve().parents[2]
AUDIT_DOC = ROOT / "docs" / "audit.md"


def check_trace_source() -> str:
    blocks = re.findall(r"```python\n(.*?)```", AUDIT_DOC.read_text(), flags=re.S)
    (source,) = [b for b in blocks if "chain.decision_link" in b]
    return source


def _export(client: TestClient, tmp_path: Path) -> tuple[Path, dict[str, str]]:
    run_id = str(client.post("/runs", json={"scenario": "baseline"}).json()["id"])
    eventually(
        lambda: client.get(f"/runs/{run_id}").json()["status"],
        until=lambda status: status == "completed",
        what=f"run {run_id} completed",
    )
    # Signed off: the export then has an annotation line, a chain of its own to check.
    signed = client.post(f"/runs/{run_id}/signoff", json={"statement": "checked on site"})
    assert signed.status_code == 201, signed.text
    export = tmp_path / f"run-{run_id}.jsonl"
    export.write_text(client.get(f"/runs/{run_id}/trace", params={"format": "jsonl"}).text)
    verify = client.get(f"/runs/{run_id}/trace/verify").json()
    assert verify["annotations_head"] is not None
    return export, {**verify["heads"], "annotations": verify["annotations_head"]}


def test_the_documented_offline_check_prints_the_heads_verify_reports(
    client: TestClient, tmp_path: Path
) -> None:
    script = tmp_path / "check_trace.py"
    script.write_text(check_trace_source())
    export, heads = _export(client, tmp_path)

    done = check_offline(export, script=script)
    assert done.returncode == 0, done.stderr
    printed = done.stdout.strip().removeprefix("ok; heads: ")
    assert ast.literal_eval(printed) == heads

    lines = export.read_text().splitlines()
    decision = json.loads(lines[5])
    assert decision["type"] == "decision"
    decision["reasoning"] += " (edited after the fact)"
    lines[5] = json.dumps(decision)
    export.write_text("\n".join(lines) + "\n")
    tampered = check_offline(export, script=script)
    assert tampered.returncode != 0
    assert "broken at decision" in tampered.stderr
