"""LLM usage derived from recorded attempts (so it survives resumes and is never doubled)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from app.graph.recorder import AttemptRecord


@dataclass
class AttemptUsage:
    llm_calls: int = 0
    input_tokens: int = 0
    output_tokens: int = 0
    transport_retries: int = 0
    latency_ms: float = 0.0


def usage_from_attempts(attempts: Iterable[AttemptRecord]) -> AttemptUsage:
    """Replies that name a model came from an LLM. The rules reasoner's carry no model, nor
    do calls the transport gave up on (nothing answered, nothing billed)."""
    usage = AttemptUsage()
    for record in attempts:
        reply = record.reply
        if reply is None or reply.model is None:
            continue
        usage.llm_calls += 1
        usage.input_tokens += reply.input_tokens
        usage.output_tokens += reply.output_tokens
        usage.transport_retries += reply.transport_retries
        usage.latency_ms += reply.latency_ms
    return usage
