"""What a reasoner is: something that answers a decision prompt in the required format."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

from app.domain.decision import DecisionContext
from app.reasoners.structured import ReplySchema


@dataclass(frozen=True)
class ReasonerReply:
    text: str
    input_tokens: int = 0
    output_tokens: int = 0
    latency_ms: float = 0.0
    model: str | None = None
    transport_retries: int = 0
    extra: dict[str, object] = field(default_factory=dict)


class ReasonerError(RuntimeError):
    """A reasoner gave no reply after its own transport retries (timeouts, 429, 5xx).

    The graph records it as a failed attempt and escalates, like an unusable answer;
    any other exception from a reasoner (bad key, unknown model) ends the run.
    """

    def __init__(self, message: str, *, transport_retries: int = 0) -> None:
        super().__init__(message)
        self.transport_retries = transport_retries  # the trace shows what the transport tried


class Reasoner(Protocol):
    """Answers one decision. With a `schema` (a structured run,
    docs/reasoners.md#structured-replies) a model is asked for that JSON object; a reasoner
    that calls no model (rules, replay) may answer in markdown all the same: the graph reads
    whatever a reply holds."""

    name: str

    def reason(
        self,
        system: str,
        user: str,
        context: DecisionContext,
        schema: ReplySchema | None = None,
    ) -> ReasonerReply: ...


class ModelCaller(Protocol):
    """One call of a language model, outside any allocation decision (the Decomposition
    Agent's too): free text without a schema, else the JSON object the schema describes,
    in at most `max_tokens` output tokens. The `anthropic` and `openai` reasoners are
    both; transport failures raise ReasonerError, refusals ReasonerRejectedError."""

    name: str

    def complete(
        self, system: str, user: str, *, schema: ReplySchema | None, max_tokens: int
    ) -> ReasonerReply: ...


def close_reasoner(reasoner: Reasoner) -> None:
    """Release what a reasoner holds (the anthropic SDK's connection pool); rules has none."""
    close = getattr(reasoner, "close", None)
    if callable(close):
        close()
