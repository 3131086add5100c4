"""The trade-off rule (docs/allocation.md#the-trade-off-rule): the one place that decides "best
robot or least-loaded robot".

The rules reasoner, the mode-compliance criterion and the fallback all call this, so the
three can never disagree about what the mode and phase require.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

from app.domain.decision import DecisionContext
from app.domain.modes import Mode, tradeoff_threshold
from app.domain.phases import Phase

DECISIVE_GAP = 25.0  # points: above this the best robot wins in every mode
NEGLIGIBLE_GAP = 5.0  # points: below this the least-loaded robot wins in every mode
# A choice this close to the deciding cut-off is a judgement call, not a clear win.
CLEAR_MARGIN = 4.0


class Branch(StrEnum):
    DECISIVE = "decisive"  # gap > 25 -> best
    NEGLIGIBLE = "negligible"  # gap < 5 -> fewest
    ABOVE_THRESHOLD = "above_threshold"  # gap > mode threshold -> best
    WITHIN_THRESHOLD = "within_threshold"  # gap <= mode threshold -> fewest


@dataclass(frozen=True)
class TradeOff:
    best: int  # highest S among cap-feasible robots
    fewest: int  # lowest load among cap-feasible robots
    gap: float  # S(best) - S(fewest), in points
    threshold: float  # the mode's (and phase's) cut-off, in points
    branch: Branch

    @property
    def choice(self) -> int:
        return (
            self.best if self.branch in (Branch.DECISIVE, Branch.ABOVE_THRESHOLD) else self.fewest
        )

    @property
    def rule_text(self) -> str:
        """The clause of the rule that decided, with its numbers."""
        g = f"{self.gap:.1f}"
        if self.branch is Branch.DECISIVE:
            return f"gap {g} > {DECISIVE_GAP:g} points, so the best robot wins"
        if self.branch is Branch.NEGLIGIBLE:
            return f"gap {g} < {NEGLIGIBLE_GAP:g} points, so the least-loaded robot wins"
        if self.branch is Branch.ABOVE_THRESHOLD:
            return f"gap {g} > threshold {self.threshold:g} points, so the best robot wins"
        return f"gap {g} <= threshold {self.threshold:g} points, so the least-loaded robot wins"


def apply_rule(
    success: Sequence[float],
    loads: Sequence[int],
    feasible: Sequence[int],
    mode: Mode,
    phase: Phase,
) -> TradeOff:
    if not feasible:
        raise ValueError("no robot can take this task without breaking the workload cap")
    # Ties: best prefers the lighter robot, fewest the more capable one, then robot order.
    best = min(feasible, key=lambda r: (-success[r], loads[r], r))
    fewest = min(feasible, key=lambda r: (loads[r], -success[r], r))
    # Rounded so that e.g. 0.90 - 0.65 is exactly 25 points, not 25.000000000000004.
    gap = round((success[best] - success[fewest]) * 100.0, 6)
    threshold = tradeoff_threshold(mode, phase)
    if gap > DECISIVE_GAP:
        branch = Branch.DECISIVE
    elif gap < NEGLIGIBLE_GAP:
        branch = Branch.NEGLIGIBLE
    elif gap > threshold:
        branch = Branch.ABOVE_THRESHOLD
    else:
        branch = Branch.WITHIN_THRESHOLD
    return TradeOff(best=best, fewest=fewest, gap=gap, threshold=threshold, branch=branch)


def rule_for(ctx: DecisionContext) -> TradeOff:
    return apply_rule(ctx.success, ctx.loads, ctx.feasible, ctx.mode, ctx.phase)


def expected_confidence(rule: TradeOff, choice: int, guided: int | None = None) -> str:
    """The confidence a well-justified answer states for `choice`.

    High when the rule decides clearly (or there is no real alternative), medium near the
    cut-off or when following optimizer guidance against the rule, low against the rule.
    """
    if choice == rule.choice:
        if rule.best == rule.fewest or rule.branch in (Branch.DECISIVE, Branch.NEGLIGIBLE):
            return "high"
        return "high" if abs(rule.gap - rule.threshold) >= CLEAR_MARGIN else "medium"
    if guided is not None and choice == guided:
        return "medium"
    return "low"
