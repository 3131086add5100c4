"""docs/estimates.md#the-model by hand: the posterior a test expects, computed from the reports it
sent (not from the service's code), for the API, end-to-end and browser tests alike."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from app.domain.catalog import scenario

STRENGTH = 10.0


def baseline_rates() -> dict[str, dict[str, float]]:
    return {r.name: dict(r.success) for r in scenario("baseline").instance.robots}


def baseline_features() -> dict[str, list[str]]:
    """Task id (as text) -> its features, on the paper's instance."""
    return {str(t.id): list(t.features) for t in scenario("baseline").instance.tasks}


@dataclass
class Tally:
    """Outcomes a test sent, by (robot, feature)."""

    counts: dict[tuple[str, str], list[int]] = field(default_factory=dict)

    def add(self, robot: str, features: Iterable[str], done: bool) -> None:
        for feature in features:
            pair = self.counts.setdefault((robot, feature), [0, 0])
            pair[0 if done else 1] += 1

    def add_reports(
        self,
        assignments: Iterable[Mapping[str, Any]],
        outcomes: Mapping[str, str],
        features: Mapping[str, list[str]],
    ) -> None:
        """`outcomes`: task id (as text) -> "done" | "failed" sent for it; the robot is the
        one the run assigned."""
        robots = {str(a["task_id"]): a["robot"] for a in assignments}
        for task_id, state in outcomes.items():
            self.add(robots[task_id], features[task_id], state == "done")

    def posterior(self, robot: str, feature: str, prior: float) -> float:
        s, f = self.counts.get((robot, feature), [0, 0])
        return (prior * STRENGTH + s) / (STRENGTH + s + f)


def estimate_of(body: Mapping[str, Any], robot: str, feature: str) -> Mapping[str, Any]:
    """One (robot, feature) row of GET /sites/{site}/estimates."""
    for row in body["robots"]:
        if row["robot"] == robot:
            for f in row["features"]:
                if f["feature"] == feature:
                    return f
    raise AssertionError(f"no estimate for {robot}/{feature} in {body}")


def assert_matches(
    body: Mapping[str, Any], tally: Tally, priors: Mapping[str, Mapping[str, float]]
) -> None:
    """Every (robot, feature) of the site equals the hand-computed posterior."""
    for robot, rates in priors.items():
        for feature, prior in rates.items():
            row = estimate_of(body, robot, feature)
            s, f = tally.counts.get((robot, feature), [0, 0])
            assert (row["successes"], row["failures"]) == (s, f), (robot, feature, row)
            assert row["prior"] == prior
            assert abs(row["posterior_mean"] - tally.posterior(robot, feature, prior)) < 1e-9
