"""Exact replay in memory: the graph fed a run's recorded replies reproduces every verdict."""

from __future__ import annotations

from typing import Any

import pytest

from app.domain.errors import DomainError
from app.graph.memory_recorder import MemoryRecorder
from app.graph.recorder import AttemptRecord
from app.graph.usage import usage_from_attempts
from app.reasoners.base import ReasonerError
from app.reasoners.factory import make_reasoner
from app.reasoners.replay import RecordedReply, ReplayDivergedError, ReplayReasoner
from app.reasoners.rules import RulesReasoner, compose_answer
from tests.fakes.scripted_reasoner import GARBAGE, ScriptedReasoner, poor_answer
from tests.support.ltaa_support import attempt_of, context, problem, reply_of, run

TRANSPORT_FAILURE = "HTTP 529 after 3 transport retries: overloaded"


def recorded(rec: MemoryRecorder) -> dict[tuple[int, int], RecordedReply]:
    """What the runs layer loads from the attempts table, from an in-memory record."""
    out = {}
    for a in rec.attempts():
        reply = a.reply
        out[(a.task_index, a.attempt)] = RecordedReply(
            text=reply.text if reply else None,
            model=reply.model if reply else None,
            input_tokens=reply.input_tokens if reply else 0,
            output_tokens=reply.output_tokens if reply else 0,
            extra=dict(reply.extra) if reply else {},
        )
    return out


def verdicts(a: AttemptRecord) -> tuple[Any, ...]:
    return (
        a.task_index,
        a.attempt,
        a.tier,
        a.user_prompt,
        a.parsed,
        a.scores,
        a.quality,
        a.accepted,
        a.hard_invalid,
        a.feedback,
        a.reply.text if a.reply else None,
    )


def test_replay_through_the_graph_reproduces_every_verdict_and_costs_nothing() -> None:
    prob = problem(n_tasks=6)
    # Task 0: poor, then fixed at tier 1. Task 1: the transport gives up once, then a good
    # answer. Task 2: garbage five times (attempts 4 and 5 both at tier 3, so a replay
    # keyed by tier would answer attempt 5 with attempt 4's text), then good at attempt 6.
    # Task 3: garbage to the end: the fallback. Tasks 4-5: good.
    scripted = ScriptedReasoner(
        script=[
            poor_answer,
            compose_answer,
            ReasonerError(TRANSPORT_FAILURE),
            compose_answer,
            *[GARBAGE] * 5,
            compose_answer,
            *[GARBAGE] * 6,
        ]
    )
    original, _ = run(prob, scripted, max_retries=5)
    assert scripted.script == []
    first = original.decisions()
    assert [d.attempts for d in first[:4]] == [2, 2, 6, 6]
    assert [d.fallback for d in first] == [False, False, False, True, False, False]
    assert "gave no reply" in (original.attempts(1)[0].feedback or "")

    replay = ReplayReasoner(run_id="orig", replies=recorded(original))
    again, _ = run(prob, replay, max_retries=5)

    assert [verdicts(a) for a in again.attempts()] == [verdicts(a) for a in original.attempts()]
    assert [vars(d) for d in again.decisions()] == [vars(d) for d in first]
    usage = usage_from_attempts(again.attempts())
    assert (usage.llm_calls, usage.input_tokens, usage.output_tokens) == (0, 0, 0)
    assert usage_from_attempts(original.attempts()).llm_calls > 0
    reply = reply_of(attempt_of(again, 0, 1))
    assert reply.model is None and reply.input_tokens == 0
    assert reply.extra == {
        "reasoner": "replay",
        "replayed_from": "orig",
        "original_model": "scripted",
        "original_input_tokens": 100,
        "original_output_tokens": 50,
    }
    failed = reply_of(attempt_of(again, 1, 1))
    assert failed.extra["error"] == TRANSPORT_FAILURE


def test_a_replay_of_a_replay_still_names_the_first_model_and_its_tokens() -> None:
    prob = problem(n_tasks=3)
    original, _ = run(prob, ScriptedReasoner(script=[GARBAGE]))
    once, _ = run(prob, ReplayReasoner(run_id="a", replies=recorded(original)))
    twice, _ = run(prob, ReplayReasoner(run_id="b", replies=recorded(once)))
    assert [verdicts(a) for a in twice.attempts()] == [verdicts(a) for a in original.attempts()]
    extra = reply_of(attempt_of(twice, 0, 2)).extra
    assert extra == {
        "reasoner": "replay",
        "replayed_from": "b",
        "original_model": "scripted",
        "original_input_tokens": 100,
        "original_output_tokens": 50,
    }


def test_a_rules_record_replays_as_text_with_no_model() -> None:
    prob = problem(n_tasks=4)
    original, _ = run(prob, RulesReasoner())
    again, _ = run(prob, ReplayReasoner(run_id="r", replies=recorded(original)))
    assert [verdicts(a) for a in again.attempts()] == [verdicts(a) for a in original.attempts()]
    assert reply_of(attempt_of(again, 0, 1)).extra["original_model"] is None


def test_an_attempt_the_original_never_made_fails_loudly() -> None:
    replay = ReplayReasoner(run_id="x", replies={(0, 1): RecordedReply(text="**Decision**: A")})
    assert replay.reason("s", "u", context(task_index=0, attempt=1)).text == "**Decision**: A"
    with pytest.raises(ReplayDivergedError, match="no attempt 2 for task index 0"):
        replay.reason("s", "u", context(task_index=0, attempt=2))
    with pytest.raises(ReasonerError, match="no reply was recorded"):
        ReplayReasoner(run_id="x", replies={(0, 1): RecordedReply(text=None)}).reason(
            "s", "u", context(task_index=0, attempt=1)
        )


def test_factory_builds_a_replay_only_from_given_replies() -> None:
    replay = make_reasoner("replay", replay_of="abc", replies={})
    assert isinstance(replay, ReplayReasoner) and replay.run_id == "abc"
    with pytest.raises(DomainError) as err:
        make_reasoner("replay")
    assert err.value.field == "reasoner" and "replay_of" in err.value.message
