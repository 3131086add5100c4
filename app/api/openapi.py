"""The OpenAPI document as the server actually behaves: with no API keys configured, every
endpoint is open, so the document declares no security (a client generated from it would
otherwise ask for a key the server never checks)."""

from __future__ import annotations

from collections.abc import Callable
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
            app.openapi_schema = without_security(document) if open_access else document
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]


def header_schema(**string: Any) -> Callable[[dict[str, Any]], None]:
    """json_schema_extra of an optional header: a string with these keywords. Optional
    means not sent; a header has no null (`str | None` would document one, and a client
    would send the text "null")."""

    def edit(schema: dict[str, Any]) -> None:
        kept: dict[str, Any] = {k: schema[k] for k in ("title", "description") if k in schema}
        schema.clear()
        schema.update(kept, type="string", **string)

    return edit
