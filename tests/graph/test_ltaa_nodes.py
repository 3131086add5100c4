"""Each of the nine nodes as a unit: called directly with a state and a Runtime."""

from __future__ import annotations

from typing import Any

import pytest
from langgraph.graph import END
from langgraph.runtime import Runtime

from app.graph import nodes
from app.graph.builder import route_after_retry, route_after_store, route_after_validate
from app.graph.memory_recorder import MemoryRecorder
from app.graph.pause import Node
from app.graph.recorder import RunCancelled
from app.graph.state import GraphContext, LTAAState, initial_state
from app.graph.validation import reasoner_failed
from app.reasoners.base import ReasonerError
from app.reasoners.rules import RulesReasoner
from tests.fakes.scripted_reasoner import GARBAGE, ScriptedReasoner, poor_answer
from tests.support.ltaa_support import as_state, attempt_of, problem

ALL_NODES: list[Node] = [
    nodes.detect_phase,
    nodes.build_prompt,
    nodes.reason,
    nodes.validate,
    nodes.build_feedback,
    nodes.retry,
    nodes.finalize,
    nodes.update_workload,
    nodes.store_and_route,
]


def setup(
    reasoner: Any = None, hook: Any = None, **kw: Any
) -> tuple[Runtime[GraphContext], MemoryRecorder]:
    rec = MemoryRecorder(before_reason_hook=hook)
    ctx = GraphContext(problem=problem(), reasoner=reasoner or RulesReasoner(), recorder=rec, **kw)
    return Runtime(context=ctx), rec


def start(rt: Runtime[GraphContext], **values: Any) -> LTAAState:
    return as_state({**initial_state(rt.context.problem), **values})


def step(state: LTAAState, node: Node, rt: Runtime[GraphContext]) -> LTAAState:
    return as_state({**state, **node(state, rt)})


def through_validate(rt: Runtime[GraphContext]) -> LTAAState:
    state = start(rt)
    for node in (nodes.detect_phase, nodes.build_prompt, nodes.reason, nodes.validate):
        state = step(state, node, rt)
    return state


def test_detect_phase_derives_the_view() -> None:
    rt, _ = setup(guidance=lambda t, loads: 2)
    state = start(rt, task_index=12, loads=[8, 2, 2])
    view = nodes.detect_phase(state, rt)["view"]
    assert view["phase"] == "middle" and view["progress"] == pytest.approx(12 / 36)
    assert view["weights"] == [0.6, 0.4] and view["guided_robot"] == 2
    assert view["severity"] == "high" and view["balance"] == pytest.approx(100 * (1 - 10 / 12))
    assert view["feasible"] == [0, 1, 2]


@pytest.mark.parametrize(
    ("t", "phase"), [(32, "early"), (33, "middle"), (66, "middle"), (67, "late")]
)
def test_phase_boundaries_at_033_and_067(t: int, phase: str) -> None:
    from app.domain.catalog import scenario
    from app.domain.models import Instance, Task
    from app.domain.problem import Problem

    robots = scenario("baseline").instance.robots
    inst = Instance(
        tasks=tuple(Task(id=i, name=f"t{i}", features=("heavy",)) for i in range(100)),
        robots=robots,
    )
    rt = Runtime(
        context=GraphContext(
            problem=Problem.build(inst), reasoner=RulesReasoner(), recorder=MemoryRecorder()
        )
    )
    state = start(rt, task_index=t, loads=[t, 0, 0])
    assert nodes.detect_phase(state, rt)["view"]["phase"] == phase


def test_build_prompt_records_attempt_one_and_never_wipes_a_reply() -> None:
    rt, rec = setup()
    state = step(start(rt), nodes.detect_phase, rt)
    assert nodes.build_prompt(state, rt) == {"attempt": 1, "tier": 0, "fallback": False}
    record = rec.attempt(0, 1)
    assert record is not None and record.tier == 0 and "Task 1/36: Stop" in record.user_prompt
    state = step(state, nodes.build_prompt, rt)
    nodes.reason(state, rt)
    nodes.build_prompt(state, rt)  # re-executed after a crash
    assert attempt_of(rec, 0, 1).reply is not None


def test_reason_calls_once_and_reuses_a_recorded_reply() -> None:
    reasoner = ScriptedReasoner()
    seen: list[tuple[int, int]] = []
    rt, rec = setup(reasoner, hook=lambda t, a: seen.append((t, a)))
    state = step(step(start(rt), nodes.detect_phase, rt), nodes.build_prompt, rt)
    assert nodes.reason(state, rt) == {}
    assert nodes.reason(state, rt) == {}  # the node re-runs after a crash
    assert len(reasoner.calls) == 1 and seen == [(0, 1)]
    reply = attempt_of(rec, 0, 1).reply
    assert reply is not None and reply.input_tokens == 100 and reply.model == "scripted"


def test_reason_records_a_transport_failure_as_an_attempt() -> None:
    rt, rec = setup(ScriptedReasoner([ReasonerError("HTTP 529 after 3 retries")]))
    state = step(step(start(rt), nodes.detect_phase, rt), nodes.build_prompt, rt)
    nodes.reason(state, rt)
    reply = attempt_of(rec, 0, 1).reply
    assert reply is not None and reply.extra["error"] == "HTTP 529 after 3 retries"
    out = nodes.validate(state, rt)
    assert out == {"accepted": False, "robot": None}
    assert "reasoner gave no reply" in (attempt_of(rec, 0, 1).hard_invalid or "")


def test_validate_scores_and_records() -> None:
    rt, rec = setup()
    state = through_validate(rt)
    assert state["accepted"] and state["robot"] == 0
    record = attempt_of(rec, 0, 1)
    assert record.accepted and record.quality == 1.0 and len(record.scores) == 8
    assert record.parsed is not None and record.parsed["robot_name"] == "light"


def test_build_feedback_and_retry_escalate() -> None:
    rt, rec = setup(ScriptedReasoner([GARBAGE]), max_retries=1)
    state = through_validate(rt)
    assert not state["accepted"]
    assert nodes.build_feedback(state, rt) == {}
    feedback = attempt_of(rec, 0, 1).feedback
    assert feedback is not None and feedback.startswith("Hard invalid (Q=0): no parseable decision")
    assert nodes.retry(state, rt) == {"attempt": 2, "tier": 1}
    tier1 = attempt_of(rec, 0, 2)
    assert tier1.tier == 1 and feedback in tier1.user_prompt
    assert nodes.retry({**state, "attempt": 2}, rt) == {"fallback": True}  # 1 + max_retries


def test_build_feedback_reuses_the_verdict_validate_reached() -> None:
    rt, rec = setup(ScriptedReasoner([poor_answer]))
    state = through_validate(rt)
    assert not state["accepted"]
    # A stand-in verdict for this very attempt: the feedback must come from it, not a re-judge.
    rt.context.verdicts.remember(0, 1, reasoner_failed("remembered"))
    nodes.build_feedback(state, rt)
    assert (attempt_of(rec, 0, 1).feedback or "").startswith(
        "Hard invalid (Q=0): the reasoner gave no reply (remembered)."
    )
    assert rt.context.verdicts.recall(0, 2) is None  # another attempt: nothing to reuse


def test_build_feedback_after_a_resume_rejudges_to_the_same_text() -> None:
    rt, rec = setup(ScriptedReasoner([poor_answer]))
    state = through_validate(rt)
    nodes.build_feedback(state, rt)
    cached = attempt_of(rec, 0, 1).feedback
    assert cached is not None
    assert cached.startswith("Q=") and "\n- " in cached
    # A resumed run gets a fresh context (empty cache) over the same recorded attempt.
    resumed = Runtime(
        context=GraphContext(problem=rt.context.problem, reasoner=RulesReasoner(), recorder=rec)
    )
    assert resumed.context.verdicts.recall(0, 1) is None
    nodes.build_feedback(state, resumed)
    assert attempt_of(rec, 0, 1).feedback == cached


def test_finalize_accepted_and_fallback() -> None:
    rt, _ = setup()
    state = through_validate(rt)
    out = nodes.finalize(state, rt)
    d = out["decision"]
    assert out["robot"] == 0 and not out["fallback"] and d["text_attempt"] == 1
    assert d["quality"] == 1.0 and d["failure_log"] == [] and d["loads_before"] == [0, 0, 0]

    rt, _ = setup(ScriptedReasoner([GARBAGE]), max_retries=0)
    state = through_validate(rt)
    nodes.build_feedback(state, rt)
    state = step(state, nodes.retry, rt)
    assert state["fallback"]
    out = nodes.finalize(state, rt)
    d = out["decision"]
    assert out["fallback"] and out["robot"] == 0  # the rules choice for task 0
    assert d["failure_log"] == [
        "attempt 1 (tier 0): Hard invalid (Q=0): no parseable decision: "
        "the answer has no **Decision** line."
    ]
    assert "Rule-based choice" in d["reasoning"] and d["quality"] >= 0.9


def test_update_workload_and_store_and_route() -> None:
    rt, rec = setup()
    state = step(through_validate(rt), nodes.finalize, rt)
    state = step(state, nodes.update_workload, rt)
    assert state["loads"] == [1, 0, 0] and state["view"]["severity"] == "high"
    out = nodes.store_and_route(state, rt)
    assert out == {"task_index": 1, "done": False, "decision": None, "failing": 0}
    [d] = rec.decisions()
    assert (d.task_index, d.task_id, d.robot_name, d.attempts, d.fallback) == (
        0,
        0,
        "light",
        1,
        False,
    )
    assert d.loads_before == [0, 0, 0] and d.loads_after == [1, 0, 0]
    assert d.reasoning.startswith("Rule-based choice") and d.confidence == "high"
    nodes.store_and_route(state, rt)  # re-run: an upsert, still one decision
    assert len(rec.decisions()) == 1
    text = {"text_attempt": None, "reasoning": "r", "tradeoff": "t"}  # as a fallback carries
    decision = state["decision"]
    assert decision is not None
    last: LTAAState = {**state, "task_index": 35, "decision": {**decision, **text}}
    assert nodes.store_and_route(last, rt)["done"] is True
    assert rec.decisions()[-1].reasoning == "r"


@pytest.mark.parametrize("node", ALL_NODES, ids=lambda n: n.__name__)
def test_every_node_checks_cancellation_first(node: Any) -> None:
    rt, rec = setup()
    rec.cancel()
    with pytest.raises(RunCancelled):
        node(start(rt), rt)


def test_routers_read_one_flag_and_tolerate_missing_keys() -> None:
    assert route_after_validate({"accepted": True}) == "finalize"
    assert route_after_validate({}) == "build_feedback"
    assert route_after_retry({"fallback": True}) == "finalize"
    assert route_after_retry({}) == "reason"
    assert route_after_store({"done": True}) == END
    assert route_after_store({}) == "detect_phase"
