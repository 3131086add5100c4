"""One HTTP attempt: a POST to a checked address, with a timeout and a capped read."""

from __future__ import annotations

import time

import httpx

from app.store.models import utcnow
from app.webhooks.queue import AttemptResult
from app.webhooks.status import AttemptOutcome
from app.webhooks.targets import Resolver, TargetRefused, resolve_target

EXCERPT_CHARS = 512  # of the response body, kept in the attempt log
USER_AGENT = "ltaa-webhooks/1"


def make_client(timeout_s: float) -> httpx.Client:
    """No redirects (a 3xx is a failed attempt: following one would skip the address
    check), no proxy or certificates from the environment, and no kept-alive connections:
    each attempt connects to the address it checked, never to one a pool kept for the
    same IP under another host name."""
    return httpx.Client(
        timeout=timeout_s,
        follow_redirects=False,
        trust_env=False,
        limits=httpx.Limits(max_keepalive_connections=0),
        headers={"user-agent": USER_AGENT},
    )


class AttemptTooSlow(httpx.TimeoutException):
    """The whole attempt took longer than the timeout (httpx times each read separately, so
    a receiver dripping its answer could otherwise hold an attempt far longer)."""


def _read_capped(response: httpx.Response, cap: int, deadline: float) -> bytes:
    body = bytearray()
    for chunk in response.iter_raw():
        body += chunk[: cap - len(body)]
        if len(body) >= cap:
            break  # the rest is never read; closing the response drops the connection
        if time.monotonic() > deadline:
            raise AttemptTooSlow("the response took longer than the timeout to arrive")
    return bytes(body)


def send(
    client: httpx.Client,
    *,
    url: str,
    body: bytes,
    headers: dict[str, str],
    resolver: Resolver,
    allow_private: bool,
    max_response_bytes: int,
    timeout_s: float,
) -> AttemptResult:
    started_at = utcnow()
    t0 = time.perf_counter()
    deadline = time.monotonic() + timeout_s

    def elapsed_ms() -> float:
        return (time.perf_counter() - t0) * 1000.0

    try:
        target = resolve_target(url, resolver=resolver, allow_private=allow_private)
    except TargetRefused as exc:
        return AttemptResult(AttemptOutcome.REFUSED, started_at, elapsed_ms(), error=str(exc))
    request = client.build_request(
        "POST",
        target.url,
        content=body,
        headers={
            **headers,
            "host": target.host_header,
            "content-type": "application/json",
        },
        # The certificate is checked against the URL's host name, not the address.
        extensions={"sni_hostname": target.server_name} if target.server_name else {},
    )
    try:
        response = client.send(request, stream=True)
        try:
            excerpt = _read_capped(response, max_response_bytes, deadline)
        finally:
            response.close()
    except httpx.HTTPError as exc:
        return AttemptResult(
            AttemptOutcome.NETWORK_ERROR,
            started_at,
            elapsed_ms(),
            error=f"{type(exc).__name__}: {exc or 'no detail'} (to {target.address})",
        )
    code = response.status_code
    text = excerpt.decode("utf-8", errors="replace")[:EXCERPT_CHARS] or None
    if 200 <= code < 300:
        return AttemptResult(
            AttemptOutcome.DELIVERED, started_at, elapsed_ms(), code, response_excerpt=text
        )
    error = f"HTTP {code}"
    if 300 <= code < 400:
        error += f": redirect to {response.headers.get('location', '?')} not followed"
    return AttemptResult(
        AttemptOutcome.HTTP_ERROR, started_at, elapsed_ms(), code, error, response_excerpt=text
    )
