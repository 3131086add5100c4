"""Helpers shared by several nodes."""

from __future__ import annotations

from app.graph.prompts import SYSTEM_PROMPT
from app.graph.recorder import AttemptRecord, Recorder


def save_prompt(recorder: Recorder, task_index: int, attempt: int, tier: int, user: str) -> None:
    """Record the prompt of an attempt, unless the attempt already has a reply.

    A node re-executed after a crash (or LangGraph bug #8039) must not wipe a reply
    that the reason node already paid for.
    """
    existing = recorder.attempt(task_index, attempt)
    if existing is not None and existing.reply is not None:
        return
    recorder.save_attempt(
        AttemptRecord(
            task_index=task_index,
            attempt=attempt,
            tier=tier,
            system_prompt=SYSTEM_PROMPT,
            user_prompt=user,
        )
    )


def require_attempt(recorder: Recorder, task_index: int, attempt: int) -> AttemptRecord:
    record = recorder.attempt(task_index, attempt)
    if record is None:
        raise RuntimeError(
            f"no attempt {attempt} recorded for task index {task_index}; the "
            "recorder lost a write the graph relies on"
        )
    return record
