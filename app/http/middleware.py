"""The app's two pure-ASGI middlewares, outermost first: RequestMetrics times every request
(a rejected body's 413 included) and BodySizeLimit answers 413 for a body over its limit.

One module of the HTTP kit: they wrap each other on every ASGI message of every request,
so they sit together at the edge (docs/development.md#the-walk-of-post-runs-and-the-worker).
"""

from __future__ import annotations

import time

from fastapi.responses import JSONResponse
from prometheus_client import Histogram
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.http.errors import ApiError, error_body


class RequestMetrics:
    """Pure ASGI (streams pass straight through): observe each request's latency, labelled
    by route template so /runs/{run_id} is one series, not one per run."""

    def __init__(self, app: ASGIApp, histogram: Histogram) -> None:
        self.app = app
        self.histogram = histogram  # app.observability.metrics.Metrics.request_seconds

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        status = 500  # an exception escaping the app becomes a 500

        async def send_status(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, send_status)
        finally:
            route = getattr(scope.get("route"), "path", None) or "unrouted"
            self.histogram.labels(scope["method"], route, str(status)).observe(
                time.perf_counter() - started
            )


class BodySizeLimit:
    """Answer 413 for bodies above `max_bytes`, whether declared (Content-Length) or streamed.

    Pure ASGI so the limit is enforced while reading, before anything is buffered or parsed.
    `paths` gives a path a limit of its own: {path: (bytes, the setting that sets it)}
    (an imported schedule file may be larger than any JSON request).
    """

    def __init__(
        self, app: ASGIApp, max_bytes: int, paths: dict[str, tuple[int, str]] | None = None
    ) -> None:
        self.app = app
        self.max_bytes = max_bytes
        self.paths = paths or {}

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit, setting = self.paths.get(
            scope.get("path", ""), (self.max_bytes, "LTAA_MAX_BODY_BYTES")
        )
        declared = dict(scope.get("headers") or []).get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > limit:
            await self._reject(scope, receive, send, int(declared), limit, setting)
            return

        seen = 0

        async def counting_receive() -> Message:
            # Streamed (chunked) bodies carry no Content-Length: count while reading.
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:
                    raise self._too_large(None, limit, setting)
            return message

        await self.app(scope, counting_receive, send)

    def _too_large(self, size: int | None, limit: int, setting: str) -> ApiError:
        amount = f"{size:,} bytes" if size is not None else "too large"
        return ApiError(
            413,
            ["body"],
            f"request body is {amount}: the limit is {limit:,} bytes "
            f"({setting}); send less or raise the limit",
            "body_too_large",
        )

    async def _reject(
        self, scope: Scope, receive: Receive, send: Send, size: int, limit: int, setting: str
    ) -> None:
        exc = self._too_large(size, limit, setting)
        body = error_body(exc.loc, str(exc.detail), exc.type)
        await JSONResponse(body, status_code=413)(scope, receive, send)
