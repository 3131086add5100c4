"""The official VDA 5050 2.1.0 JSON schemas, for checking every message the tests see.

They come from the vda5050-sdk package (a pinned dev dependency, MIT), whose files are
byte-identical to json_schemas/ of the VDA5050/VDA5050 repository at tag 2.1.0: their
sha256 are pinned in tests/fleet/test_vda5050_schemas.py, so a different copy fails there.
"""

from __future__ import annotations

import json
from functools import cache
from importlib import resources
from typing import Any

import jsonschema

KINDS = ("order", "state", "instantActions", "connection", "factsheet")


def schema_bytes(kind: str) -> bytes:
    return (resources.files("vda5050") / "validation" / "schemas" / f"{kind}.json").read_bytes()


@cache
def _validator(kind: str) -> Any:
    schema = json.loads(schema_bytes(kind))
    cls = jsonschema.validators.validator_for(schema)
    return cls(schema, format_checker=cls.FORMAT_CHECKER)


def validate(kind: str, message: dict[str, Any]) -> None:
    """Raise jsonschema.ValidationError unless the message is a valid VDA 5050 `kind`."""
    _validator(kind).validate(message)
