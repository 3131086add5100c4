"""The eight criteria, each with a passing and a failing answer, and the hard invalids."""

from __future__ import annotations

import re
from dataclasses import replace

import pytest

from app.graph.validation import WEIGHTS, validate_text
from app.reasoners.base import DecisionContext
from app.reasoners.rules import compose_answer
from tests.support.ltaa_support import context

CTX = context()  # middle phase, balanced; rule picks Heavy Robot (gap 40 > 25)
GOOD = compose_answer(CTX)


def section(text: str, name: str, value: str | None) -> str:
    """Replace (or with None, drop) one section of an answer."""
    lines = text.splitlines()
    out = []
    for line in lines:
        if line.startswith(f"**{name}**"):
            if value is not None:
                out.append(f"**{name}**: {value}")
        else:
            out.append(line)
    return "\n".join(out)


def scores(text: str, ctx: DecisionContext = CTX) -> dict[str, float]:
    return validate_text(text, ctx).scores


def test_weights_are_the_papers() -> None:
    assert WEIGHTS == {
        "explanation": 0.20,
        "success_accuracy": 0.20,
        "tradeoff_analysis": 0.15,
        "workload_awareness": 0.15,
        "mode_compliance": 0.10,
        "phase_consistency": 0.10,
        "logical_consistency": 0.05,
        "confidence_justification": 0.05,
    }
    assert sum(WEIGHTS.values()) == pytest.approx(1.0)


def test_the_rules_answer_passes_every_criterion() -> None:
    v = validate_text(GOOD, CTX)
    assert v.accepted and v.hard_invalid is None and v.robot == 2
    assert v.scores == dict.fromkeys(WEIGHTS, 1.0) and v.quality == 1.0


def test_quality_is_the_weighted_sum_and_threshold_decides() -> None:
    text = section(GOOD, "Expected Success", "70%")
    v = validate_text(text, CTX)
    assert v.quality == pytest.approx(sum(WEIGHTS[k] * q for k, q in v.scores.items()), abs=1e-4)
    assert validate_text(text, CTX, threshold=v.quality).accepted
    assert not validate_text(text, CTX, threshold=v.quality + 0.01).accepted


def test_explanation() -> None:
    assert scores(GOOD)["explanation"] == 1.0
    assert scores(section(GOOD, "Reasoning", "Because."))["explanation"] < 0.5
    assert scores(section(GOOD, "Reasoning", None))["explanation"] == 0.0
    no_numbers = "Heavy Robot is strong at this. It is the middle phase and it wins the rule."
    assert scores(section(GOOD, "Reasoning", no_numbers))["explanation"] == 0.75


def test_success_rate_accuracy() -> None:
    assert scores(section(GOOD, "Expected Success", "0.9"))["success_accuracy"] == 1.0
    assert scores(section(GOOD, "Expected Success", "89%"))["success_accuracy"] == 1.0
    partial = scores(section(GOOD, "Expected Success", "82%"))["success_accuracy"]
    assert 0.0 < partial < 1.0
    assert scores(section(GOOD, "Expected Success", "70%"))["success_accuracy"] == 0.0
    assert scores(section(GOOD, "Expected Success", None))["success_accuracy"] == 0.0


def test_tradeoff_analysis() -> None:
    assert scores(GOOD)["tradeoff_analysis"] == 1.0
    assert scores(section(GOOD, "Trade-Off Summary", None))["tradeoff_analysis"] == 0.0
    vague = scores(section(GOOD, "Trade-Off Summary", "Heavy Robot is fine."))
    assert vague["tradeoff_analysis"] == 0.25


def test_workload_awareness() -> None:
    # true loads before: 3/5/6; choosing Heavy Robot gives 3/5/7
    assert scores(GOOD)["workload_awareness"] == 1.0
    one_wrong = "Light Robot: 3, Medium Robot: 5, Heavy Robot: 6"
    assert scores(section(GOOD, "Workload After Assignment", one_wrong))[
        "workload_awareness"
    ] == pytest.approx(2 / 3, abs=1e-4)
    assert scores(section(GOOD, "Workload After Assignment", None))["workload_awareness"] == 0.0


def test_mode_compliance() -> None:
    assert scores(GOOD)["mode_compliance"] == 1.0
    fewest = section(GOOD, "Decision", "Light Robot")  # the other rule candidate
    assert scores(fewest)["mode_compliance"] == 0.5
    neither = section(GOOD, "Decision", "Medium Robot")
    assert scores(neither)["mode_compliance"] == 0.0
    # Optimizer guidance, when present, is a compliant choice.
    assert scores(neither, replace(CTX, guided_robot=1))["mode_compliance"] == 1.0


def test_phase_consistency() -> None:
    assert scores(GOOD)["phase_consistency"] == 1.0
    wrong = GOOD.replace("middle phase", "late phase")
    assert scores(wrong)["phase_consistency"] == 0.0
    both = GOOD.replace("middle phase", "middle phase (not the early phase)")
    assert scores(both)["phase_consistency"] == 0.5
    none = re.sub(r"This is the middle phase of", "In", GOOD)
    assert scores(none)["phase_consistency"] == 0.2


def test_logical_consistency() -> None:
    assert scores(GOOD)["logical_consistency"] == 1.0
    other_robot = "Medium Robot at 70% is decent. The middle phase favours balance somewhat."
    assert scores(section(GOOD, "Reasoning", other_robot))["logical_consistency"] == 0.5
    # An expected success that belongs to another robot contradicts the decision.
    assert scores(section(GOOD, "Expected Success", "70%"))["logical_consistency"] == 0.5


def test_confidence_justification() -> None:
    assert scores(GOOD)["confidence_justification"] == 1.0  # decisive gap: High
    assert scores(section(GOOD, "Confidence Level", "Medium"))["confidence_justification"] == 0.5
    assert scores(section(GOOD, "Confidence Level", "low"))["confidence_justification"] == 0.0
    assert scores(section(GOOD, "Confidence Level", None))["confidence_justification"] == 0.0


@pytest.mark.parametrize(
    ("text", "ctx", "why"),
    [
        ("I would rather not choose.", CTX, "no parseable decision"),
        (section(GOOD, "Decision", "Tower Crane"), CTX, "unknown robot"),
        (GOOD, replace(CTX, feasible=(0, 1)), "workload cap infeasible"),
        # docs/allocation.md#teams: the Heavy Robot's skills rule the task out
        (
            GOOD,
            replace(CTX, feasible=(0, 1), eligible=(True, True, False)),
            "Heavy Robot cannot take this task",
        ),
    ],
)
def test_hard_invalids_score_zero(text: str, ctx: DecisionContext, why: str) -> None:
    v = validate_text(text, ctx)
    assert v.quality == 0.0 and not v.accepted
    assert v.hard_invalid is not None and why in v.hard_invalid
    assert set(v.scores.values()) == {0.0}
