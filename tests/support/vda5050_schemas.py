"""The official VDA 5050 2.1.0 JSON schemas, for checking every message the tests see.

They are shipped in tests/fleet/data/vda5050/: copies of json_schemas/ of the public
VDA5050/VDA5050 repository at tag 2.1.0 (MIT), whose sha256 are pinned in
tests/fleet/test_vda5050_schemas.py, so an edited copy fails there.
"""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path
from typing import Any

import jsonschema

KINDS = ("order", "state", "instantActions", "connection", "factsheet")
SCHEMAS = Path(__file__).resolve().parents[1] / "fleet" / "data" / "vda5050"


def schema_bytes(kind: str) -> bytes:
    return (SCHEMAS / f"{kind}.schema.json").read_bytes()


@cache
def _validator(kind: str) -> Any:
    schema = json.loads(schema_bytes(kind))
    cls = jsonschema.validators.validator_for(schema)
    return cls(schema, format_checker=cls.FORMAT_CHECKER)


def validate(kind: str, message: dict[str, Any]) -> None:
    """Raise jsonschema.ValidationError unless the message is a valid VDA 5050 `kind`."""
    _validator(kind).validate(message)
