"""The trade-off rule (docs/allocation.md#the-trade-off-rule): every branch, every mode/phase
threshold, tie-breaks."""

from __future__ import annotations

import pytest

from app.domain.modes import Mode
from app.domain.phases import Phase
from app.domain.tradeoff import Branch, TradeOff, apply_rule, expected_confidence


def rule(
    s_best: float, s_fewest: float, mode: Mode = Mode.BALANCED, phase: Phase = Phase.MIDDLE
) -> TradeOff:
    # robot 0 is the most capable but loaded; robot 1 is the least loaded.
    return apply_rule([s_best, s_fewest], [5, 2], [0, 1], mode, phase)


def test_gap_above_25_picks_best_in_every_mode() -> None:
    for mode in Mode:
        r = rule(0.90, 0.60, mode, Phase.LATE)
        assert (r.branch, r.choice, r.gap) == (Branch.DECISIVE, 0, 30.0)


def test_gap_below_5_picks_fewest_in_every_mode() -> None:
    for mode in Mode:
        r = rule(0.74, 0.70, mode, Phase.EARLY)
        assert (r.branch, r.choice) == (Branch.NEGLIGIBLE, 1)


@pytest.mark.parametrize(
    ("mode", "phase", "threshold"),
    [
        (Mode.SUCCESS_FOCUSED, Phase.EARLY, 8),
        (Mode.SUCCESS_FOCUSED, Phase.LATE, 8),
        (Mode.AGGRESSIVE_BALANCE, Phase.EARLY, 18),
        (Mode.AGGRESSIVE_BALANCE, Phase.MIDDLE, 18),
        (Mode.BALANCED, Phase.EARLY, 8),
        (Mode.BALANCED, Phase.MIDDLE, 13),
        (Mode.BALANCED, Phase.LATE, 18),
    ],
)
def test_middle_band_compares_gap_with_mode_threshold(
    mode: Mode, phase: Phase, threshold: int
) -> None:
    above = rule(0.50 + (threshold + 1) / 100, 0.50, mode, phase)
    at = rule(0.50 + threshold / 100, 0.50, mode, phase)
    assert above.threshold == threshold
    assert (above.branch, above.choice) == (Branch.ABOVE_THRESHOLD, 0)
    assert (at.branch, at.choice) == (Branch.WITHIN_THRESHOLD, 1)  # "exceeds" is strict


def test_boundaries_are_exact_despite_float_noise() -> None:
    # 0.90 - 0.65 is 25.000000000000004 points in floats: it must count as exactly 25.
    r = rule(0.90, 0.65, Mode.AGGRESSIVE_BALANCE)
    assert r.gap == 25.0 and r.branch is Branch.ABOVE_THRESHOLD
    r5 = rule(0.75, 0.70, Mode.SUCCESS_FOCUSED)
    assert r5.gap == 5.0 and r5.branch is Branch.WITHIN_THRESHOLD  # 5 is not < 5, not > 8


def test_only_cap_feasible_robots_are_considered() -> None:
    r = apply_rule([0.9, 0.5, 0.6], [0, 4, 5], [1, 2], Mode.BALANCED, Phase.EARLY)
    assert (r.best, r.fewest) == (2, 1)
    with pytest.raises(ValueError):
        apply_rule([0.9], [0], [], Mode.BALANCED, Phase.EARLY)


def test_ties_break_toward_lighter_best_and_stronger_fewest() -> None:
    r = apply_rule([0.8, 0.8, 0.6], [3, 1, 1], [0, 1, 2], Mode.BALANCED, Phase.EARLY)
    assert r.best == 1 and r.fewest == 1 and r.choice == 1


def test_expected_confidence() -> None:
    clear = rule(0.90, 0.60)  # decisive
    assert expected_confidence(clear, clear.choice) == "high"
    near = rule(0.64, 0.50)  # gap 14 vs threshold 13: 1 point from the cut-off
    assert expected_confidence(near, near.choice) == "medium"
    assert expected_confidence(near, 1 - near.choice) == "low"
    assert expected_confidence(near, 1 - near.choice, guided=1 - near.choice) == "medium"
