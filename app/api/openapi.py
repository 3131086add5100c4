"""The OpenAPI document as the server actually behaves: with no API keys configured, every
endpoint is open, so the document declares no security (a client generated from it would
otherwise ask for a key the server never checks)."""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi


def without_security(document: dict[str, Any]) -> dict[str, Any]:
    for operations in document.get("paths", {}).values():
        for operation in operations.values():
            if isinstance(operation, dict):
                # 401/403 stay documented: their descriptions say they apply only
                # when LTAA_API_KEYS is set, and a client may meet a server that sets it.
                operation.pop("security", None)
    document.get("components", {}).pop("securitySchemes", None)
    return document


# Two answer models share a class name (a run's LLM attempt and a webhook delivery attempt),
# so the document names each after its module. The modules moved into feature packages
# (issue 28); the names stay those first published, so generated clients keep their types.
PUBLISHED_NAMES = {
    "app__runs__trace_schemas__AttemptOut": "app__api__schemas__trace__AttemptOut",
    "app__webhooks__schemas__AttemptOut": "app__api__schemas__webhooks__AttemptOut",
}
_REF_PREFIX = "#/components/schemas/"


def with_published_names(document: dict[str, Any]) -> dict[str, Any]:
    schemas = document.get("components", {}).get("schemas", {})
    for moved, published in PUBLISHED_NAMES.items():
        if moved in schemas:
            schemas[published] = schemas.pop(moved)
    document["components"]["schemas"] = dict(sorted(schemas.items())) if schemas else schemas
    _rename_refs(document)
    return document


def _rename_refs(node: Any) -> None:
    if isinstance(node, dict):
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.startswith(_REF_PREFIX):
            name = ref.removeprefix(_REF_PREFIX)
            node["$ref"] = _REF_PREFIX + PUBLISHED_NAMES.get(name, name)
        for value in node.values():
            _rename_refs(value)
    elif isinstance(node, list):
        for value in node:
            _rename_refs(value)


def install_openapi(app: FastAPI, *, open_access: bool) -> None:
    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            document = get_openapi(
                title=app.title,
                version=app.version,
                openapi_version=app.openapi_version,
                summary=app.summary,
                description=app.description,
                routes=app.routes,
            )
            document = with_published_names(document)
            app.openapi_schema = without_security(document) if open_access else document
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
