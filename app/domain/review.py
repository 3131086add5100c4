"""Supervisor review of decisions (docs/reviews.md#which-decisions-wait-for-review): the policy a
run is created with, the triggers it fires on the true facts of a decision, and the vocabulary of a
resolution.

Pure rules; the graph evaluates them at each decision and app.reviews.service stores them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from enum import StrEnum
from typing import Any

from app.domain.errors import DomainError
from app.domain.models import Instance


class ReviewOn(StrEnum):
    """Conditions named in a policy's `on` list."""

    FALLBACK = "fallback"
    LOW_CONFIDENCE = "low_confidence"
    EVERY_DECISION = "every_decision"


class Trigger(StrEnum):
    """Why a decision was sent for review (each listed condition that held)."""

    FALLBACK = "fallback"
    LOW_CONFIDENCE = "low_confidence"
    EVERY_DECISION = "every_decision"
    QUALITY_BELOW = "quality_below"
    REGRET_ABOVE = "regret_above"
    TASK_IDS = "task_ids"
    FEATURES = "features"
    ROBOTS = "robots"


class ReviewAction(StrEnum):
    APPROVE = "approve"
    OVERRIDE = "override"


class ReviewState(StrEnum):
    PENDING = "pending"
    RESOLVED = "resolved"
    CLOSED = "closed"  # the run was cancelled or revised while the review waited


@dataclass(frozen=True)
class Proposal:
    """The true facts of a proposed decision that the triggers read."""

    task_id: str
    features: Sequence[str]
    robot: str
    fallback: bool
    confidence: str
    quality: float
    # Success points given away over the rest of the queue against the exact optimum (the
    # unit of the guidance costs); None when unknown.
    regret_points: float | None
    # A team decision (docs/reviews.md#reviews-of-team-decisions): every member's name; `robot`
    # is the first unit's. Empty for one robot.
    members: tuple[str, ...] = ()


@dataclass(frozen=True)
class ReviewPolicy:
    on: tuple[ReviewOn, ...] = ()
    quality_below: float | None = None
    regret_above: float | None = None
    task_ids: tuple[str, ...] = ()
    features: tuple[str, ...] = ()
    robots: tuple[str, ...] = ()

    def triggers(self, p: Proposal) -> list[Trigger]:
        fired: list[Trigger] = []
        if ReviewOn.EVERY_DECISION in self.on:
            fired.append(Trigger.EVERY_DECISION)
        if ReviewOn.FALLBACK in self.on and p.fallback:
            fired.append(Trigger.FALLBACK)
        # The accepted reply's Confidence Level; a fallback has no accepted reply.
        low = not p.fallback and p.confidence.strip().lower() == "low"
        if ReviewOn.LOW_CONFIDENCE in self.on and low:
            fired.append(Trigger.LOW_CONFIDENCE)
        if self.quality_below is not None and p.quality < self.quality_below:
            fired.append(Trigger.QUALITY_BELOW)
        if (
            self.regret_above is not None
            and p.regret_points is not None
            and p.regret_points > self.regret_above
        ):
            fired.append(Trigger.REGRET_ABOVE)
        if p.task_id in self.task_ids:
            fired.append(Trigger.TASK_IDS)
        if set(p.features) & set(self.features):
            fired.append(Trigger.FEATURES)
        if p.robot in self.robots or set(p.members) & set(self.robots):
            fired.append(Trigger.ROBOTS)  # a team: any of its members
        return fired

    def to_json(self) -> dict[str, Any]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ReviewPolicy:
        return cls(
            on=tuple(ReviewOn(x) for x in data.get("on", ())),
            quality_below=data.get("quality_below"),
            regret_above=data.get("regret_above"),
            task_ids=tuple(str(x) for x in data.get("task_ids", ())),
            features=tuple(data.get("features", ())),
            robots=tuple(data.get("robots", ())),
        )


@dataclass(frozen=True)
class Resolution:
    """A supervisor's answer to one review: what the paused graph is resumed with."""

    action: ReviewAction
    reviewer: str
    at: str  # RFC 3339
    triggers: tuple[str, ...] = field(default_factory=tuple)
    robot: str | None = None  # override only: the reviewer's robot (by name)
    reason: str | None = None  # required for an override
    # Override of a team decision only: (robot, feature) per unit, in unit order; `robot` is
    # then the first unit's member (docs/reviews.md#reviews-of-team-decisions).
    team: tuple[tuple[str, str], ...] | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "action": self.action.value,
            "reviewer": self.reviewer,
            "at": self.at,
            "triggers": list(self.triggers),
            "robot": self.robot,
            "reason": self.reason,
        }
        if self.team is not None:  # absent for one robot: those resolutions read as before
            out["team"] = [{"robot": r, "feature": f} for r, f in self.team]
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Resolution:
        return cls(
            action=ReviewAction(data["action"]),
            reviewer=str(data["reviewer"]),
            at=str(data["at"]),
            triggers=tuple(data.get("triggers") or ()),
            robot=data.get("robot"),
            reason=data.get("reason"),
            team=None
            if data.get("team") is None
            else tuple((str(m["robot"]), str(m["feature"])) for m in data["team"]),
        )


def check_review_policy(policy: ReviewPolicy, instance: Instance) -> None:
    """DomainError naming the field for a robot, feature or task id the instance lacks: a
    policy that names them could never fire, which is a mistake, not a preference."""
    robots = {r.name for r in instance.robots}
    features = set(instance.features) | {f for r in instance.robots for f in r.success}
    task_ids = {str(t.id) for t in instance.tasks}
    checks = (
        ("robots", policy.robots, robots, "robot"),
        ("features", policy.features, features, "feature"),
        ("task_ids", policy.task_ids, task_ids, "task id"),
    )
    for name, given, known, noun in checks:
        for i, value in enumerate(given):
            if value not in known:
                raise DomainError(
                    f"review.{name}.{i}", f"unknown {noun} '{value}' in this run's instance"
                )
