"""The review policy's triggers on the true facts of a proposal, and the unit of
`regret_above`: success points over the rest of the queue, as the guidance costs."""

from __future__ import annotations

from dataclasses import replace

import pytest

from app.domain.models import Instance, Robot, Task
from app.domain.problem import Problem
from app.domain.review import Proposal, ReviewOn, ReviewPolicy, Trigger
from app.graph.memory_recorder import MemoryRecorder
from app.reasoners.rules import RulesReasoner
from app.solvers.ltaa import graph_context
from app.solvers.oracle import CompletionOracle

PROPOSAL = Proposal(
    task_id="T0",
    features=("heavy",),
    robot="a",
    fallback=False,
    confidence="High",
    quality=0.9,
    regret_points=0.0,
)


def test_no_policy_fires_nothing_and_every_decision_fires_always() -> None:
    assert ReviewPolicy().triggers(PROPOSAL) == []
    assert ReviewPolicy(on=(ReviewOn.EVERY_DECISION,)).triggers(PROPOSAL) == [
        Trigger.EVERY_DECISION
    ]


@pytest.mark.parametrize(
    ("policy", "proposal", "fired"),
    [
        (ReviewPolicy(on=(ReviewOn.FALLBACK,)), replace(PROPOSAL, fallback=True), ["fallback"]),
        (ReviewPolicy(on=(ReviewOn.FALLBACK,)), PROPOSAL, []),
        (
            ReviewPolicy(on=(ReviewOn.LOW_CONFIDENCE,)),
            replace(PROPOSAL, confidence=" low "),
            ["low_confidence"],
        ),
        # A fallback has no accepted reply, so no reply's confidence to judge.
        (
            ReviewPolicy(on=(ReviewOn.LOW_CONFIDENCE,)),
            replace(PROPOSAL, confidence="Low", fallback=True),
            [],
        ),
        (ReviewPolicy(quality_below=0.95), PROPOSAL, ["quality_below"]),
        (ReviewPolicy(quality_below=0.9), PROPOSAL, []),
        (ReviewPolicy(regret_above=5.0), replace(PROPOSAL, regret_points=5.01), ["regret_above"]),
        (ReviewPolicy(regret_above=5.0), replace(PROPOSAL, regret_points=5.0), []),
        (ReviewPolicy(task_ids=("T0",)), PROPOSAL, ["task_ids"]),
        (ReviewPolicy(features=("careful", "heavy")), PROPOSAL, ["features"]),
        (ReviewPolicy(robots=("b",)), PROPOSAL, []),
        (ReviewPolicy(robots=("a",), task_ids=("T9",)), PROPOSAL, ["robots"]),
    ],
)
def test_each_condition_fires_exactly_where_it_holds(
    policy: ReviewPolicy, proposal: Proposal, fired: list[str]
) -> None:
    assert [t.value for t in policy.triggers(proposal)] == fired


def test_the_policy_round_trips_through_the_run_spec_json() -> None:
    policy = ReviewPolicy(
        on=(ReviewOn.FALLBACK, ReviewOn.LOW_CONFIDENCE),
        quality_below=0.8,
        regret_above=5.0,
        task_ids=("1", "T2"),
        features=("heavy",),
        robots=("heavy",),
    )
    assert ReviewPolicy.from_json(policy.to_json()) == policy


def test_regret_above_is_measured_in_points_over_the_queue_not_per_task() -> None:
    """36 tasks: a per-task mean would divide the give-away by 36 and never reach 5."""
    instance = Instance(
        tasks=tuple(Task(id=i, name=f"t{i}", features=("heavy",)) for i in range(36)),
        robots=(
            Robot(name="strong", success={"heavy": 0.9}),
            Robot(name="weak", success={"heavy": 0.5}),
        ),
    )
    problem = Problem.build(instance, max_deviation=None, uncapped=True)
    ctx = graph_context(
        problem,
        reasoner=RulesReasoner(),
        recorder=MemoryRecorder(),
        quality_threshold=0.6,
        max_retries=0,
        guidance=None,
        review=ReviewPolicy(regret_above=5.0),
    )
    assert ctx.review is not None
    cost = ctx.review.cost(0, [0, 0], 1)  # the weak robot for the first task
    assert cost is not None and cost == pytest.approx(40.0)  # (0.9 - 0.5) x 100 over the queue
    # The same unit as the optimizer guidance shows the reasoner.
    guided = CompletionOracle(problem).guidance(0, [0, 0])
    assert guided is not None and guided.costs[1] == pytest.approx(cost)
    # The per-decision regret of the record is the per-task mean of the same give-away.
    assert ctx.regret is not None and ctx.regret(0, [0, 0], (1,)) == pytest.approx(cost / 100 / 36)
    fires = ReviewPolicy(regret_above=5.0).triggers(replace(PROPOSAL, regret_points=cost))
    assert fires == [Trigger.REGRET_ABOVE]
