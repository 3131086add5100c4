"""HTTP shapes of a run's audit record: the chain verification and the JSON-lines export."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

from fastapi.responses import StreamingResponse
from sqlalchemy.orm import Session, sessionmaker

from app.audit.export import trace_record
from app.audit.verify import ChainReport
from app.runs.trace_schemas import (
    BrokenLinkOut,
    ChainHeadsOut,
    ParentLinkOut,
    SignatureOut,
    TraceVerifyOut,
)

JSONL = "application/x-ndjson"

# OpenAPI 3.1 has no per-line schema for a JSON-lines body (3.2's itemSchema), so the body
# is documented as what it is on the wire: text, one JSON object per line.
JSONL_RESPONSE: dict[str, Any] = {
    "description": "format=json (default): the trace as one JSON document. format=jsonl: the "
    "whole audit record streamed as JSON lines.",
    "content": {
        JSONL: {
            "schema": {
                "type": "string",
                "description": "One JSON object per line, each with a `type`: first `run` (the "
                "run, its stored request and the genesis of its two hash chains), then every "
                "`event` in seq order, then every `decision` in task order with its "
                "`attempt_records` (prompts, replies, scores, verdicts), then every `annotation` "
                "in seq order (what was recorded after the run finished: sign-offs, execution "
                "reports, superseded_by; their own chain), all under their stored column names "
                "with their `chain_hash`; last an `end` line with the counts, so a cut-off "
                "download is recognisable.",
            }
        }
    },
}


def _encoded(pages: Iterator[list[dict[str, Any]]]) -> Iterator[str]:
    # One chunk per page, not per line: each chunk is a hop to a worker thread.
    for page in pages:
        yield "".join(json.dumps(line, ensure_ascii=False) + "\n" for line in page)


def jsonl_trace(*, sessions: sessionmaker[Session], run_id: str) -> StreamingResponse:
    """Raises RunNotFoundError (a 404) before any byte is sent."""
    pages = trace_record(sessions=sessions, run_id=run_id)
    return StreamingResponse(_encoded(pages), media_type=JSONL)


def verify_out(report: ChainReport) -> TraceVerifyOut:
    broken = report.first_break
    return TraceVerifyOut(
        ok=report.ok,
        decisions=report.decisions.rows,
        events=report.events.rows,
        annotations=report.annotations.rows,
        signoffs_ok=report.signoffs_ok,
        unchained=report.decisions.unchained
        + report.events.unchained
        + report.annotations.unchained,
        heads=ChainHeadsOut(decisions=report.decisions.head, events=report.events.head),
        chain_scheme=report.chain_scheme,
        signature=None
        if report.signature is None
        else SignatureOut(
            key_id=report.signature.key_id,
            reason=report.signature.reason,
            valid=report.signature.valid,
            problem=report.signature.problem,
        ),
        annotations_head=report.annotations.head,
        parent=None
        if report.parent_link is None
        else ParentLinkOut(
            run_id=report.parent_link.parent,
            ok=report.parent_link.ok,
            reason=report.parent_link.reason,
        ),
        broken=None
        if broken is None
        else BrokenLinkOut(
            table=broken.table,
            task_index=broken.key if broken.table == "decisions" else None,
            seq=broken.key if broken.table != "decisions" else None,
            expected=broken.expected,
            stored=broken.stored,
            reason=broken.reason,
        ),
    )
