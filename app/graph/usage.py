"""LLM usage derived from recorded attempts (so it survives resumes and is never doubled)."""

from __future__ import annotations

from collections.abc import Iterable

from app.domain.usage import ReplyUsage, Usage
from app.graph.recorder import AttemptRecord


def usage_from_attempts(attempts: Iterable[AttemptRecord]) -> Usage:
    """Counted by the rule of `Usage.from_replies`; an attempt without a reply used nothing."""
    return Usage.from_replies(
        ReplyUsage(r.model, r.input_tokens, r.output_tokens, r.transport_retries, r.latency_ms)
        for r in (record.reply for record in attempts)
        if r is not None
    )
