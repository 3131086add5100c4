"""GET /runs/{id}/events: a run's live progress as Server-Sent Events."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import AsyncIterator
from datetime import datetime
from typing import Annotated

from fastapi import APIRouter, Depends, Header, Query
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import StreamingResponse

from app.http.deps import SettingsDep, StreamSupervisorDep
from app.http.errors import ApiError
from app.http.responses import SUPERVISOR, errors, header_schema
from app.runs.deps import RunIdPath, RunsDep
from app.runs.progress import CURSOR_PATTERN, Cursor, read_progress, run_status, task_ids
from app.store.tombstones import missing_run

router = APIRouter(prefix="/runs", tags=["runs"])

RECONNECT_MS = 1000


def existing_run(run_id: RunIdPath, runs: RunsDep) -> str:
    # A dependency, so an unknown id is a 404 before the stream (and its 200) begins.
    if run_status(sessions=runs.sessions, run_id=run_id) is None:
        with runs.sessions() as session:
            raise missing_run(session, run_id)
    return run_id


def start_cursor(
    last_event_id: Annotated[
        str | None,
        Header(
            alias="Last-Event-ID",
            # Documented here, checked below (a 422 with this stream's own wording). Empty
            # or blank is "from the start", as a reconnecting EventSource may send.
            json_schema_extra=header_schema(pattern=rf"^[ \t]*$|{CURSOR_PATTERN}"),
            description="The `id` of the last event received, e.g. `3-17`: the stream "
            "continues after it",
        ),
    ] = None,
    after: Annotated[
        str | None,
        Query(
            max_length=32,
            json_schema_extra=header_schema(maxLength=32, pattern=rf"^[ \t]*$|{CURSOR_PATTERN}"),
            description="Start after this event id (as Last-Event-ID does; EventSource "
            "cannot send that header on its first request). The header wins on a reconnect.",
        ),
    ] = None,
) -> Cursor:
    text, loc = (
        (last_event_id, ["header", "last-event-id"])
        if last_event_id and last_event_id.strip(" \t")
        else (after, ["query", "after"])
    )
    if not text or not text.strip(" \t"):
        return Cursor()
    try:
        return Cursor.parse(text)
    except ValueError as exc:
        raise ApiError(422, loc, str(exc), "value_error") from None


def _json_value(value: object) -> str:
    # Times as RFC 3339 (like every other response), not str()'s "2026-11-23 02:28:33+00:00".
    return value.isoformat() if isinstance(value, datetime) else str(value)


def sse(
    *,
    event: str | None = None,
    id: str | None = None,
    data: object = None,
    retry: int | None = None,
    comment: str | None = None,
) -> str:
    """One Server-Sent Event in the text/event-stream wire format."""
    lines = [f": {comment}"] if comment is not None else []
    if id is not None:
        lines.append(f"id: {id}")
    if event is not None:
        lines.append(f"event: {event}")
    if retry is not None:
        lines.append(f"retry: {retry}")
    if data is not None:
        lines.append(f"data: {json.dumps(data, separators=(',', ':'), default=_json_value)}")
    return "\n".join(lines) + "\n\n"


# A plain StreamingResponse rather than fastapi.sse.EventSourceResponse: the latter's
# keep-alive task logs a BrokenResourceError traceback whenever a client hangs up.
@router.get(
    "/{run_id}/events",
    response_class=StreamingResponse,
    responses={200: {"content": {"text/event-stream": {}}}, **errors(*SUPERVISOR, 404, 410)},
)
async def run_events(
    caller: StreamSupervisorDep,  # first: who may ask is settled before whether the run exists
    run_id: Annotated[str, Depends(existing_run)],
    cursor: Annotated[Cursor, Depends(start_cursor)],
    runs: RunsDep,
    settings: SettingsDep,
) -> StreamingResponse:
    """For supervisors: one `run` event per run event and one `decision` event per
    finalised decision, in order; review requests, resolutions and closings are `review`
    events (same data as `run`); a `status` event (`status`, `finished`) on connecting and
    whenever the run's status changes, `finished` on the last; the stream ends when the run
    does. Reconnect with
    Last-Event-ID to continue where a stream stopped. Besides API keys, this one endpoint
    also accepts the supervisor console's session cookie (its pages use EventSource)."""
    headers = {"Cache-Control": "no-cache", "X-Accel-Buffering": "no"}
    return StreamingResponse(
        _stream(run_id, cursor, runs, settings), media_type="text/event-stream", headers=headers
    )


async def _stream(
    run_id: str, cursor: Cursor, runs: RunsDep, settings: SettingsDep
) -> AsyncIterator[str]:
    deadline = time.monotonic() + settings.events_max_stream_s
    retry: int | None = RECONNECT_MS
    sent_status: str | None = None
    ids = await run_in_threadpool(task_ids, sessions=runs.sessions, run_id=run_id)
    while True:
        batch = await run_in_threadpool(
            read_progress, sessions=runs.sessions, run_id=run_id, cursor=cursor, ids=ids
        )
        if batch is None:
            return
        for item in batch.items:
            yield sse(event=item.kind, id=str(item.cursor), data=item.data, retry=retry)
            retry = None
        cursor = batch.cursor
        if batch.status != sent_status:
            # Not every status change writes an event (a requeue, a hand-over between
            # processes does not), so watchers get the status itself rather than having
            # to infer it from event kinds. After the rows: a finished status is the
            # stream's last word, and a watcher may hang up on it.
            data = {"status": batch.status, "finished": batch.ended}
            yield sse(event="status", id=str(cursor), data=data, retry=retry)
            retry, sent_status = None, batch.status
        if batch.ended:
            return
        if runs.worker.draining:
            # uvicorn waits for open responses before it lets the app shut down.
            yield sse(comment="server shutting down; reconnect with Last-Event-ID")
            return
        if time.monotonic() >= deadline:
            yield sse(
                comment="stream time limit (LTAA_EVENTS_MAX_STREAM_S) reached; "
                "reconnect with Last-Event-ID"
            )
            return
        await asyncio.sleep(settings.events_poll_s)
