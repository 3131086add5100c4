"""The OpenAPI document's paths and component schemas stay what they were before the code
moved into feature packages (issue 28): a move that renames a schema, drops a route or
changes a model shows here as a diff against tests/api/snapshots/openapi.json.

A deliberate change to the API regenerates the snapshot:
`PYTHONPATH=. python -m tests.api.test_openapi_snapshot` (then review the diff)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from pydantic import SecretStr

from app.config import Settings
from app.main import create_app

SNAPSHOT = Path(__file__).with_name("snapshots") / "openapi.json"
# With keys configured, so the document carries its security requirements too.
KEYS = SecretStr("snapshot-supervisor-key-0123456:supervisor")


def document(data_dir: Path) -> dict[str, Any]:
    """The parts a client is generated from: every path with its operations, and every
    component schema. (The app's title, version and summary are not the API's shape.)"""
    settings = Settings(
        data_dir=data_dir,
        api_keys=KEYS,
        anthropic_api_key=None,
        anthropic_base_url=None,
        openai_base_url=None,
        openai_api_key=None,
        openai_model=None,
    )
    full = create_app(settings).openapi()
    # A JSON round trip: the snapshot file holds JSON, so tuples compare as lists.
    parts = {"paths": full["paths"], "schemas": full["components"]["schemas"]}
    loaded: dict[str, Any] = json.loads(json.dumps(parts))
    _unify_shared_operation_ids(loaded["paths"])
    return loaded


def _unify_shared_operation_ids(paths: dict[str, Any]) -> None:
    """One function serving several methods (GET and HEAD /health) gets one operationId
    for all of them, built from whichever method its set yields first: that varies with
    the interpreter's hash seed, so the snapshot holds a fixed stand-in instead."""
    for operations in paths.values():
        ids = [op.get("operationId") for op in operations.values() if isinstance(op, dict)]
        if len(ids) > 1 and len(set(ids)) == 1:
            for operation in operations.values():
                operation["operationId"] = "(shared by this path's methods)"


def test_openapi_paths_and_schemas_match_the_snapshot(tmp_path: Path) -> None:
    expected = json.loads(SNAPSHOT.read_text(encoding="utf-8"))
    actual = document(tmp_path / "data")
    assert sorted(actual["paths"]) == sorted(expected["paths"])
    assert sorted(actual["schemas"]) == sorted(expected["schemas"])
    for path, operations in expected["paths"].items():
        assert actual["paths"][path] == operations, f"path {path} differs from the snapshot"
    for name, schema in expected["schemas"].items():
        assert actual["schemas"][name] == schema, f"schema {name} differs from the snapshot"


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as scratch:
        parts = document(Path(scratch) / "data")
    SNAPSHOT.parent.mkdir(parents=True, exist_ok=True)
    SNAPSHOT.write_text(json.dumps(parts, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    sys.stdout.write(f"wrote {SNAPSHOT} ({len(parts['paths'])} paths)\n")
