"""Exact replay: a finished run's recorded replies, answered again with no API call.

The graph is deterministic given the replies (prompts, validation, feedback, fallback and
regret are pure functions of the instance, the run parameters and the reply texts), so
feeding a run's replies back in order reproduces its allocation and every verdict.

What a replayed reply reports: it costs nothing, so it carries no model, no tokens and no
latency, and the replay run's usage shows 0 LLM calls. Which model originally answered,
and what that answer cost, stays in the reply's `extra` (`replayed_from`,
`original_model`, `original_input_tokens`, `original_output_tokens`).

An attempt whose original call failed in transport (no reply; `extra.error` recorded)
raises the same ReasonerError message again, so its feedback and failure log match.
Replies the original run got from the rules reasoner (its default, or after a token
budget ran out) are replayed as text like any other.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from app.domain.decision import DecisionContext
from app.reasoners.base import ReasonerError, ReasonerReply
from app.reasoners.structured import ReplySchema

ReplyKey = tuple[int, int]  # (task_index, attempt)


@dataclass(frozen=True)
class RecordedReply:
    """One attempt's reply as the original run stored it (attempts table)."""

    text: str | None  # None: nothing was recorded
    model: str | None = None
    input_tokens: int = 0
    output_tokens: int = 0
    extra: Mapping[str, Any] = field(default_factory=dict)

    @property
    def error(self) -> str | None:
        """Why the original call gave no reply (the transport gave up), if it did not."""
        if self.text is None:
            return "no reply was recorded"
        error = self.extra.get("error")
        return str(error) if error else None

    @property
    def answered_by(self) -> str | None:
        """The model that wrote the text; a replay of a replay names the first one."""
        return self.model or self.extra.get("original_model")

    @property
    def original_tokens(self) -> tuple[int, int]:
        """(input, output) tokens the first run paid for this text."""
        if self.model is None and "replayed_from" in self.extra:
            return (
                int(self.extra.get("original_input_tokens") or 0),
                int(self.extra.get("original_output_tokens") or 0),
            )
        return self.input_tokens, self.output_tokens


class ReplayDivergedError(RuntimeError):
    """The replay asked for an attempt the original run never made. This cannot happen
    while prompts and validation are unchanged; if it does, the run fails with this
    message rather than inventing an answer, since the replay could no longer be exact."""


class ReplayReasoner:
    name = "replay"

    def __init__(self, *, run_id: str, replies: Mapping[ReplyKey, RecordedReply]) -> None:
        self.run_id = run_id
        self._replies = replies

    def reason(
        self,
        system: str,
        user: str,
        context: DecisionContext,
        schema: ReplySchema | None = None,
    ) -> ReasonerReply:
        key = (context.task_index, context.attempt)
        recorded = self._replies.get(key)
        if recorded is None:
            raise ReplayDivergedError(
                f"run '{self.run_id}' recorded no attempt {context.attempt} for task index "
                f"{context.task_index}; the replay no longer follows the original run. This "
                "happens when prompts or validation changed since that run was recorded: "
                "replay it with the version that recorded it, or start a new run"
            )
        if recorded.error is not None:
            raise ReasonerError(recorded.error)
        input_tokens, output_tokens = recorded.original_tokens
        return ReasonerReply(
            text=recorded.text or "",
            extra={
                "replayed_from": self.run_id,
                "original_model": recorded.answered_by,
                "original_input_tokens": input_tokens,
                "original_output_tokens": output_tokens,
            },
        )
