"""Prompts: compact tier 0 carrying every fact, and three genuinely different retry tiers."""

from __future__ import annotations

from dataclasses import replace

from app.graph.prompts import (
    SYSTEM_PROMPT,
    TARGET_USER_PROMPT_CHARS,
    prompt_for,
    prompt_size,
    retry_prompt,
    user_prompt,
)
from tests.support.ltaa_support import context

CTX = context()


def test_user_prompt_carries_the_facts_and_is_compact() -> None:
    text = user_prompt(CTX)
    for needle in (
        "Task 15/36: Double Forward (Motion)",
        "features: heavy",
        "Light Robot [light]: S 50.0%, load 3",
        "Heavy Robot [heavy]: S 90.0%, load 6",
        "Target load W = 12.0",
        "final loads in [8, 16]",
        "Phase: middle",
        "Mode: balanced",
        "60:40",
        "Gap > 25: best",
        "Gap < 5: fewest",
        "gap > 13",
        "**Decision**",
        "**Expected Success**",
        "**Reasoning**",
        "**Workload After Assignment**",
        "**Confidence Level**",
        "**Trade-Off Summary**",
        "**Robot Analysis**",
    ):
        assert needle in text, needle
    size = prompt_size(CTX)
    assert size["user_chars"] == len(text) <= TARGET_USER_PROMPT_CHARS
    assert size["system_chars"] == len(SYSTEM_PROMPT)


def test_cap_forbidden_robots_and_guidance_are_marked() -> None:
    text = user_prompt(replace(CTX, feasible=(0, 1), guided_robot=1))
    assert "Heavy Robot [heavy]: S 90.0%, load 6 (dev -6.0), NOT allowed" in text
    assert "Optimizer guidance: Medium Robot" in text
    assert "no workload cap" in user_prompt(replace(CTX, load_bounds=None))


def test_retry_tiers_are_genuinely_different() -> None:
    feedback = "Q=0.30 below the threshold 0.60; weakest: success-rate accuracy 0.00."
    tiers = [prompt_for(CTX, 0)] + [retry_prompt(CTX, t, feedback, 0.3, 0.6) for t in (1, 2, 3)]
    assert len(set(tiers)) == 4
    assert feedback in tiers[1] and tiers[1].startswith(tiers[0])  # tier 1: + feedback
    assert "Worked example" in tiers[2] and "How answers are scored" in tiers[2]
    assert "Worked example" not in tiers[1] and "Worked example" not in tiers[3]
    assert "fill in the template" in tiers[3] and "1. Allowed robots" in tiers[3]
    assert "Q=0.30, needed 0.60" in tiers[3]
    assert retry_prompt(CTX, 5, feedback, 0.3, 0.6) == tiers[3]  # above 3: still tier 3


def test_every_retry_tier_keeps_the_optimizer_guidance() -> None:
    guided = replace(CTX, guided_robot=1, guided_costs=(2.5, 0.0, None))
    for tier in (1, 2, 3):
        text = retry_prompt(guided, tier, "Q=0.30 below the threshold 0.60.", 0.3, 0.6)
        assert "Optimizer guidance: Medium Robot" in text, tier
        assert "Light Robot 2.5, Medium Robot 0.0, Heavy Robot not allowed" in text, tier
    assert "Optimizer guidance" not in retry_prompt(CTX, 3, "x", 0.3, 0.6)
