"""The tolerant answer parser: bold or not, % or fraction, label or key, any case."""

from __future__ import annotations

import pytest

from app.graph.parsing import find_robot, parse_probability, parse_response

NAMES = ("light", "medium", "heavy")
LABELS = ("Light Robot", "Medium Robot", "Heavy Robot")

BOLD = """**Decision**: Heavy Robot
**Expected Success**: 90%
**Reasoning**: Heavy Robot has 90% success. It is the middle phase.
**Workload After Assignment**: Light Robot: 3, Medium Robot: 5, Heavy Robot: 7
**Confidence Level**: High
**Trade-Off Summary**: best Heavy Robot vs least-loaded Light Robot, gap 40 points.
**Robot Analysis** (optional): Light Robot 50%"""

PLAIN = """decision: heavy
EXPECTED SUCCESS - 0.9
Reasoning:
Heavy Robot has 90% success.
It is the middle phase.
workload after assignment: light=3, MEDIUM=5, heavy 7 tasks
confidence: high
trade-off summary: heavy vs light, gap 40 points"""

VARIANTS = """## Decision
**Heavy Robot**
- **Expected Success:** 90.0 %
1. **Reasoning:** The heavy robot wins.
**Workload After Assignment:**
- Light Robot (light): 3
- Medium Robot: 5
- Heavy Robot: 7
**Confidence Level:** MEDIUM
**Tradeoff Summary:** fine"""


@pytest.mark.parametrize("text", [BOLD, PLAIN, VARIANTS])
def test_same_answer_in_different_dress(text: str) -> None:
    p = parse_response(text, NAMES, LABELS)
    assert p.robot == 2
    assert p.expected_success == pytest.approx(0.9)
    assert p.workload_after == {0: 3, 1: 5, 2: 7}
    assert p.confidence in ("high", "medium")
    assert p.reasoning and "heavy" in p.reasoning.lower()
    assert p.tradeoff


def test_multiline_reasoning_is_kept_and_optional_section_read() -> None:
    p = parse_response(PLAIN, NAMES, LABELS)
    assert p.reasoning == "Heavy Robot has 90% success.\nIt is the middle phase."
    assert parse_response(BOLD, NAMES, LABELS).robot_analysis == "Light Robot 50%"
    assert parse_response(PLAIN, NAMES, LABELS).robot_analysis is None


@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("80%", 0.8),
        ("0.8", 0.8),
        ("80", 0.8),
        ("80.5 percent", 0.805),
        ("~ 72.5%", 0.725),
        ("1", 1.0),
        ("none", None),
    ],
)
def test_probabilities(text: str, value: float | None) -> None:
    assert parse_probability(text) == (pytest.approx(value) if value is not None else None)


@pytest.mark.parametrize(
    ("text", "robot"),
    [
        ("Heavy Robot", 2),
        ("heavy", 2),
        ("HEAVY ROBOT (heavy)", 2),
        ("the light robot", 0),
        ("Medium Robot over Heavy Robot", 1),
        ("Robot Z", None),
        ("heavyweight", None),
    ],
)
def test_robot_by_label_or_key(text: str, robot: int | None) -> None:
    assert find_robot(text, NAMES, LABELS) == robot


def test_missing_and_unknown_decisions() -> None:
    empty = parse_response("I cannot decide.", NAMES, LABELS)
    assert empty.decision_text is None and empty.robot is None
    unknown = parse_response("**Decision**: Crane 7", NAMES, LABELS)
    assert unknown.decision_text == "Crane 7" and unknown.robot is None


def test_prose_mentioning_a_section_word_is_not_a_header() -> None:
    text = "**Decision**: Light Robot\n**Reasoning**: Decision framework says fewest wins."
    p = parse_response(text, NAMES, LABELS)
    assert p.robot == 0 and p.reasoning == "Decision framework says fewest wins."


def test_to_dict_uses_robot_keys() -> None:
    d = parse_response(BOLD, NAMES, LABELS).to_dict(NAMES)
    assert d["robot_name"] == "heavy" and d["workload_after"] == {
        "light": 3,
        "medium": 5,
        "heavy": 7,
    }
