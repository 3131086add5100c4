"""What a run's LLM calls used, and the one rule that counts them.

A reply that names a model came from an LLM: it is one call, and its tokens, transport
retries and latency count. The rules reasoner's replies name no model, nor do calls the
transport gave up on (nothing answered, nothing billed). The graph's recorded attempts,
the stored attempt rows and the `ltaa` solver all count through `Usage.from_replies`, so a
durable run and a synchronous solve report the same numbers.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import NamedTuple


class ReplyUsage(NamedTuple):
    """What one recorded reply says about its cost."""

    model: str | None
    input_tokens: int
    output_tokens: int
    transport_retries: int = 0
    latency_ms: float = 0.0


@dataclass(frozen=True)
class Usage:
    llm_calls: int = 0
    input_tokens: int = 0
    output_tokens: int = 0
    transport_retries: int = 0
    latency_ms: float = 0.0

    @classmethod
    def from_replies(cls, replies: Iterable[ReplyUsage]) -> Usage:
        billed = [r for r in replies if r.model is not None]
        return cls(
            llm_calls=len(billed),
            input_tokens=sum(r.input_tokens for r in billed),
            output_tokens=sum(r.output_tokens for r in billed),
            transport_retries=sum(r.transport_retries for r in billed),
            latency_ms=sum((r.latency_ms for r in billed), 0.0),
        )
