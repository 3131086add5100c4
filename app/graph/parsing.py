"""Tolerant parser for the required markdown answer.

Accepts bold or plain headers, `Name:` or `**Name**:` or `**Name:**` or `## Name`,
percentages or fractions, robots by label or key, any letter case. It never raises:
whatever it cannot read is left as None and validation scores it.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

_SECTION_PATTERNS: dict[str, str] = {
    "decision": r"(?:final\s+)?decision",
    "expected_success": r"expected\s+success(?:\s+rate|\s+probability)?",
    "reasoning": r"reasoning",
    "workload_after": r"workload(?:\s+after(?:\s+assignment)?)?",
    "confidence": r"confidence(?:\s+level)?",
    "tradeoff": r"trade[\s-]?off(?:\s+summary)?",
    "robot_analysis": r"robot\s+analysis",
    "team": r"team(?:\s+(?:members|composition|assignment))?",
}
_NAMES = "|".join(f"(?P<{key}>{pattern})" for key, pattern in _SECTION_PATTERNS.items())
_HEADER = re.compile(
    r"^\s*(?P<lead>#{1,6}\s*|[-*+>]\s+|\d+[.)]\s+)?"
    r"(?P<b1>\*\*|__)?\s*(?:" + _NAMES + r")(?![\w-])\s*(?P<c1>:)?\s*(?P<b2>\*\*|__)?"
    r"\s*(?:\([^)\n]*\)\s*)?(?P<c2>[:\-–—])?\s*(?P<value>.*)$",
    re.IGNORECASE,
)
_NUMBER = re.compile(r"(\d+(?:\.\d+)?)\s*(%|percent)?", re.IGNORECASE)
_CONFIDENCE = re.compile(r"\b(high|medium|low)\b", re.IGNORECASE)
_COUNT_AFTER = r"[^\d\n,;|]*?(\d+)"  # a robot's name, then the first number after it
_SENTENCE_END = re.compile(r"(?<=[.!?])\s+(?=\S)")


@dataclass
class ParsedResponse:
    decision_text: str | None = None  # the Decision value as written
    robot: int | None = None  # index of the robot it names, if any
    expected_success: float | None = None  # as a fraction
    reasoning: str | None = None
    workload_after: dict[int, int] = field(default_factory=dict)  # robot index -> count
    confidence: str | None = None  # "high" | "medium" | "low"
    tradeoff: str | None = None
    robot_analysis: str | None = None
    # docs/reasoners.md#the-response-format, a team task: one entry per line of the **Team**
    # block: {"feature", "robot" (index or None), "text" (the robot as written), "reason"}.
    team: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self, robot_names: Sequence[str]) -> dict[str, Any]:
        """JSON-friendly, with robots by key (for the attempt record)."""
        out = asdict(self)
        out["robot_name"] = robot_names[self.robot] if self.robot is not None else None
        out["workload_after"] = {robot_names[r]: n for r, n in self.workload_after.items()}
        if not self.team:
            del out["team"]  # single-robot attempts keep the record they always had
        else:
            out["team"] = [
                {**line, "robot": None if line["robot"] is None else robot_names[line["robot"]]}
                for line in self.team
            ]
        return out


def _clean(text: str) -> str:
    text = re.sub(r"(\*\*|__|`)", "", text)
    return text.strip().strip("*_").strip()


def split_sections(text: str) -> dict[str, str]:
    """Header name -> its text (header line value plus continuation lines)."""
    sections: dict[str, list[str]] = {}
    current: str | None = None
    for line in text.splitlines():
        m = _HEADER.match(line)
        is_header = bool(
            m and ((m["b1"] and m["b2"]) or m["c1"] or m["c2"] or (m["lead"] or "").startswith("#"))
        )
        if m and is_header:
            key = next(k for k in _SECTION_PATTERNS if m[k] is not None)
            if key not in sections:
                current = key
                sections[key] = [m["value"]]
                continue
        # Continuation lines, and a repeated header, belong to the section being read.
        if current is not None:
            sections[current].append(line)
    return {k: _clean("\n".join(v)) for k, v in sections.items()}


def _aliases(names: Sequence[str], labels: Sequence[str]) -> tuple[tuple[str, int], ...]:
    return _aliases_of(tuple(names), tuple(labels))


@functools.lru_cache(maxsize=64)
def _aliases_of(names: tuple[str, ...], labels: tuple[str, ...]) -> tuple[tuple[str, int], ...]:
    # Cached: a run asks for the same fleet's aliases several times per reply.
    pairs = {
        (alias.strip().lower(), i)
        for i in range(len(names))
        for alias in (labels[i], names[i])
        if alias and alias.strip()
    }
    # Longest first, so "Heavy Robot" wins over a key "heavy" at the same place.
    return tuple(sorted(pairs, key=lambda p: -len(p[0])))


def _alias_pattern(alias: str) -> str:
    return r"(?<![\w-])" + re.escape(alias) + r"(?![\w-])"


@functools.lru_cache(maxsize=256)
def _alias_regex(alias: str, suffix: str = "") -> re.Pattern[str]:
    return re.compile(_alias_pattern(alias) + suffix)


def find_robot(text: str, names: Sequence[str], labels: Sequence[str]) -> int | None:
    """The robot named first in `text` (by label or key, any case), or None."""
    lowered = text.lower()
    found: list[tuple[int, int, int]] = []
    for alias, i in _aliases(names, labels):
        m = _alias_regex(alias).search(lowered)
        if m:
            found.append((m.start(), -len(alias), i))
    return min(found)[2] if found else None


def mentioned_robots(text: str, names: Sequence[str], labels: Sequence[str]) -> set[int]:
    lowered = text.lower()
    return {i for alias, i in _aliases(names, labels) if _alias_regex(alias).search(lowered)}


def parse_probability(text: str) -> float | None:
    """`80%`, `80 percent`, `0.8` or a bare `80` -> 0.8."""
    m = _NUMBER.search(text)
    if not m:
        return None
    value = float(m.group(1))
    if m.group(2) or value > 1.0:
        value /= 100.0
    return value


def parse_workload(text: str, names: Sequence[str], labels: Sequence[str]) -> dict[int, int]:
    """`Light Robot: 5, medium=4, HEAVY 3 tasks` -> {0: 5, 1: 4, 2: 3}."""
    lowered = text.lower()
    out: dict[int, int] = {}
    for alias, i in _aliases(names, labels):
        if i in out:
            continue
        m = _alias_regex(alias, _COUNT_AFTER).search(lowered)
        if m:
            out[i] = int(m.group(1))
    return out


def count_sentences(text: str) -> int:
    return len([s for s in _SENTENCE_END.split(text.strip()) if s.strip()]) if text.strip() else 0


_BULLET = re.compile(r"^\s*(?:[-*+>•]|\d+[.)])\s*")
_HEAD = re.compile(r"\s*(?::|->|→|=>|=)\s*")
_REASON = re.compile(r"\s+[—–-]+\s+|\s*[:;]\s+|\s*\(\s*|,\s+(?=because|as|since)|\s+because\s+")


def _first_of(text: str, words: Sequence[str]) -> str | None:
    lowered = text.lower()
    found = [
        (m.start(), -len(w), w)
        for w in words
        if (m := _alias_regex(w.lower()).search(lowered)) is not None
    ]
    return min(found)[2] if found else None


def parse_team(
    text: str, features: Sequence[str], names: Sequence[str], labels: Sequence[str]
) -> list[dict[str, Any]]:
    """The **Team** block, one unit per line: `- heavy: Heavy Robot — why`, `heavy -> HR1:
    why`, `1. careful: light (because ...)`; lines naming no feature are skipped."""
    out: list[dict[str, Any]] = []
    for raw in text.splitlines():
        line = _BULLET.sub("", _clean(raw)).strip()
        if not line:
            continue
        parts = _HEAD.split(line, maxsplit=1)
        feature = _first_of(parts[0], features) if len(parts) == 2 else None
        named_first = feature is not None  # `feature: robot ...`
        rest = parts[1] if named_first else line
        if feature is None:
            feature = _first_of(line, features)
        if feature is None:
            continue
        clause, *why = _REASON.split(rest, maxsplit=1)
        robot = find_robot(clause, names, labels)
        if robot is None and not named_first:
            robot = find_robot(rest, names, labels)
        out.append(
            {
                "feature": feature,
                "robot": robot,
                "text": clause.strip(),
                "reason": (why[0] if why else "").strip().rstrip(")").strip(),
            }
        )
    return out


def parse_response(
    text: str, names: Sequence[str], labels: Sequence[str], features: Sequence[str] = ()
) -> ParsedResponse:
    sections = split_sections(text or "")
    parsed = ParsedResponse()
    decision = sections.get("decision")
    if decision:
        parsed.decision_text = decision.splitlines()[0].strip() or decision
        parsed.robot = find_robot(decision, names, labels)
    if sections.get("expected_success"):
        parsed.expected_success = parse_probability(sections["expected_success"])
    parsed.reasoning = sections.get("reasoning") or None
    if sections.get("workload_after"):
        parsed.workload_after = parse_workload(sections["workload_after"], names, labels)
    if sections.get("confidence"):
        m = _CONFIDENCE.search(sections["confidence"])
        parsed.confidence = m.group(1).lower() if m else None
    parsed.tradeoff = sections.get("tradeoff") or None
    parsed.robot_analysis = sections.get("robot_analysis") or None
    if features and sections.get("team"):
        parsed.team = parse_team(sections["team"], features, names, labels)
    return parsed
