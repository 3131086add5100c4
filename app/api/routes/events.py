"""GET /runs/{id}/events: a run's live progress as Server-Sent Events."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import APIRouter, Depends, Header
from fastapi.concurrency import run_in_threadpool
from fastapi.sse import EventSourceResponse, ServerSentEvent

from app.api.deps import RunsDep, SettingsDep, SupervisorDep
from app.api.errors import ApiError
from app.runs.errors import RunNotFoundError
from app.runs.progress import Cursor, read_progress, run_status

router = APIRouter(prefix="/runs", tags=["runs"])

RECONNECT_MS = 1000


def existing_run(run_id: str, runs: RunsDep) -> str:
    # A dependency, so an unknown id is a 404 before the stream (and its 200) begins.
    if run_status(sessions=runs.sessions, run_id=run_id) is None:
        raise RunNotFoundError(run_id)
    return run_id


def start_cursor(
    last_event_id: Annotated[str | None, Header(alias="Last-Event-ID")] = None,
) -> Cursor:
    if not last_event_id:
        return Cursor()
    try:
        return Cursor.parse(last_event_id)
    except ValueError as exc:
        raise ApiError(422, ["header", "last-event-id"], str(exc), "value_error") from None


@router.get("/{run_id}/events", response_class=EventSourceResponse)
async def run_events(
    caller: SupervisorDep,  # first: who may ask is settled before whether the run exists
    run_id: Annotated[str, Depends(existing_run)],
    cursor: Annotated[Cursor, Depends(start_cursor)],
    runs: RunsDep,
    settings: SettingsDep,
) -> AsyncIterator[ServerSentEvent]:
    """For supervisors: one `run` event per run event and one `decision` event per
    finalised decision, in order; the stream ends when the run does. Reconnect with
    Last-Event-ID to continue where a stream stopped."""
    deadline = time.monotonic() + settings.events_max_stream_s
    retry: int | None = RECONNECT_MS
    while True:
        batch = await run_in_threadpool(read_progress, sessions=runs.sessions, run_id=run_id,
                                        cursor=cursor)
        if batch is None:
            return
        for item in batch.items:
            yield ServerSentEvent(event=item.kind, id=str(item.cursor), data=item.data,
                                  retry=retry)
            retry = None
        cursor = batch.cursor
        if batch.ended:
            return
        if time.monotonic() >= deadline:
            yield ServerSentEvent(comment="stream time limit (LTAA_EVENTS_MAX_STREAM_S) "
                                          "reached; reconnect with Last-Event-ID")
            return
        await asyncio.sleep(settings.events_poll_s)
