"""What the soft criteria look for in a response's text, shared by the one-robot and the
team validation (docs/allocation.md#validation): numbers cited, the two sides of a
trade-off, the trade-off summary's score and the stated workload's."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

NUMBER_CITED = re.compile(
    r"\d+(?:\.\d+)?\s*%|\b0?\.\d+\b|\b\d+(?:\.\d+)?\s*points?\b", re.IGNORECASE
)
SUCCESS_TERMS = re.compile(r"success|\d\s*%|\bpoints?\b|\bgap\b", re.IGNORECASE)
LOAD_TERMS = re.compile(r"load|balance|\btasks?\b|least[- ]loaded|fewest", re.IGNORECASE)


def score_tradeoff(
    text: str, *, success_side: str, compares: bool, no_alternative: str
) -> tuple[float, str]:
    """The **Trade-Off Summary**: a quarter for being there, one for quantifying the success
    side (`success_side` names it in the feedback), one for loads or balance, one when it
    `compares` an alternative (else `no_alternative` is the feedback)."""
    if not text.strip():
        return 0.0, "the **Trade-Off Summary** section is missing"
    q, problems = 0.25, []
    if SUCCESS_TERMS.search(text):
        q += 0.25
    else:
        problems.append(f"it does not quantify the success side ({success_side})")
    if LOAD_TERMS.search(text):
        q += 0.25
    else:
        problems.append("it does not mention loads or balance")
    if compares:
        q += 0.25
    else:
        problems.append(no_alternative)
    return q, "; ".join(problems)


def score_workload(
    stated: Mapping[int, int] | None, after: Sequence[int], labels: Sequence[str]
) -> tuple[float, str]:
    """**Workload After Assignment**: the share of robots whose stated count is `after`'s."""
    truth = ", ".join(f"{labels[r]}: {after[r]}" for r in range(len(after)))
    if not stated:
        return 0.0, f"no **Workload After Assignment** counts (true: {truth})"
    right = sum(1 for r, n in enumerate(after) if stated.get(r) == n)
    if right == len(after):
        return 1.0, ""
    return right / len(after), f"{right} of {len(after)} counts are right (true: {truth})"
