"""`Annotated` dependency aliases that every feature's endpoints take as parameters: the
settings and the caller's role (the run store's are app.runs.deps)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Annotated

from fastapi import Depends, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer

from app.config import Settings
from app.http.auth import Caller, KeyRing, Role
from app.http.errors import ApiError

log = logging.getLogger("ltaa.auth")


async def get_app_settings(request: Request) -> Settings:
    # The instance create_app() was given, not a fresh read of the environment.
    settings: Settings = request.app.state.settings
    return settings


SettingsDep = Annotated[Settings, Depends(get_app_settings)]


# -- access control ----------------------------------------------------------------------
# Declared as security schemes so /docs offers "Authorize"; auto_error=False because a
# missing key is answered below, in the one error shape, and not at all when access is open.
_bearer = HTTPBearer(
    auto_error=False,
    scheme_name="bearer",
    description="An API key from LTAA_API_KEYS: `Authorization: Bearer <key>`",
)
_api_key_header = APIKeyHeader(
    name="X-API-Key",
    auto_error=False,
    scheme_name="apiKey",
    description="The same API key in an `X-API-Key` header",
)


def _unauthenticated(loc: str, msg: str, type_: str, challenge: str) -> ApiError:
    return ApiError(401, ["header", loc], msg, type_, headers={"WWW-Authenticate": challenge})


# The auth dependencies are `async def` although they never await: they are a dictionary
# look-up, and a plain `def` would make each one a separate job on the shared threadpool,
# queued behind every solve of a burst.
async def authenticate(
    request: Request,
    bearer: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
    header_key: Annotated[str | None, Depends(_api_key_header)],
) -> Caller:
    keyring: KeyRing = request.app.state.keyring
    if keyring.open:
        return Caller(role=Role.SUPERVISOR, anonymous=True)
    if bearer and header_key and bearer.credentials != header_key:
        # Which one is meant is anyone's guess; answering for either could act for the wrong
        # caller (a proxy's key and the client's own, say).
        raise _unauthenticated(
            "x-api-key",
            "the Authorization and X-API-Key headers carry "
            "different API keys: send one key, in one header",
            "conflicting_api_keys",
            "Bearer",
        )
    presented, loc = (bearer.credentials, "authorization") if bearer else (header_key, "x-api-key")
    if not presented:
        hint = (
            "the Authorization header must use the Bearer scheme"
            if request.headers.get("authorization")
            else "an API key is required"
        )
        raise _unauthenticated(
            "authorization",
            f"{hint}: send 'Authorization: Bearer <key>' or 'X-API-Key: <key>'",
            "missing_api_key",
            "Bearer",
        )
    found = keyring.identify(presented)
    if found is None:
        # Where and from whom, never what: the rejected value may be a real key mistyped.
        log.warning(
            "rejected an unknown API key on %s %s from %s",
            request.method,
            request.url.path,
            request.client.host if request.client else "?",
        )
        raise _unauthenticated(
            loc, "the API key is not valid", "invalid_api_key", 'Bearer error="invalid_token"'
        )
    role, name = found
    return Caller(role=role, anonymous=False, name=name)


def _check_role(caller: Caller, required: Role) -> Caller:
    if not caller.role.allows(required):
        raise ApiError(
            403,
            ["header", "authorization"],
            f"this endpoint needs the {required.value} role; the API key sent "
            f"has the {caller.role.value} role",
            "insufficient_role",
        )
    return caller


async def require_client(caller: Annotated[Caller, Depends(authenticate)]) -> Caller:
    return _check_role(caller, Role.CLIENT)


async def require_supervisor(caller: Annotated[Caller, Depends(authenticate)]) -> Caller:
    return _check_role(caller, Role.SUPERVISOR)


# The supervisor console's sign-in (app.console, installed by app.main) as a hook: it reads
# the request's session cookie and answers with the signed-in caller or None. Only the
# read-only event stream consults it, because EventSource cannot send headers; every
# other endpoint of the JSON API takes API keys only, so no cross-site form can reach one.
StreamCookieAuth = Callable[[Request], Caller | None]


async def require_stream_supervisor(
    request: Request,
    bearer: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
    header_key: Annotated[str | None, Depends(_api_key_header)],
) -> Caller:
    hook: StreamCookieAuth | None = getattr(request.app.state, "stream_cookie_auth", None)
    if hook is not None and not bearer and not header_key:
        caller = await run_in_threadpool(hook, request)  # a database read
        if caller is not None:
            return _check_role(caller, Role.SUPERVISOR)
    return _check_role(await authenticate(request, bearer, header_key), Role.SUPERVISOR)


# Clients allocate and create and read runs; supervisors may also read traces, live events
# and metrics, and resume or cancel runs.
ClientDep = Annotated[Caller, Depends(require_client)]
SupervisorDep = Annotated[Caller, Depends(require_supervisor)]
StreamSupervisorDep = Annotated[Caller, Depends(require_stream_supervisor)]
