"""Bodies of the /sites endpoints (docs/estimates.md#sites): the sites and their estimates."""

from __future__ import annotations

from pydantic import BaseModel, Field

from app.http.times import Timestamp


# A site is named like a robot or a feature (no NUL: PostgreSQL refuses it in a query).
class SiteOut(BaseModel):
    site: str
    runs: int = Field(description="Runs that name the site")
    reports: int = Field(description="Tasks reported done or failed on its runs")
    last_run_at: Timestamp | None


class FeatureEstimateOut(BaseModel):
    feature: str
    prior: float = Field(
        description="The prior mean: the configured rate of the most recent run on the site "
        "naming the robot (0.5 when no run rates the feature)"
    )
    configured: bool = Field(description="Whether a run configured the prior (else 0.5)")
    prior_strength: float = Field(description="The prior's weight, in pseudo-observations")
    successes: int
    failures: int
    posterior_mean: float
    interval: tuple[float, float] = Field(description="Central 90% credible interval")
    shift: float = Field(description="posterior_mean - prior")
    marked: bool = Field(
        description="The reports put the configured rate outside the 90% interval, and the "
        "learned rate is among the three farthest from it (the console marks these)"
    )


class DurationOut(BaseModel):
    task_type: str
    planned_minutes: float | None = Field(
        description="Mean configured duration of the reported tasks "
        "(docs/estimates.md#the-model); null for "
        "untimed runs"
    )
    observed: int = Field(
        description="started -> done (or failed) pairs that taught a duration: both with "
        "`at`, or sent in separate requests"
    )
    left_out: dict[str, int] = Field(
        default_factory=dict,
        description="Pairs whose outcome counts but that taught no duration, by reason: "
        "'together_without_at' (started and done sent in one request, not both with `at`: "
        "the times are the server's, not the site's), 'zero_length' (the same time for "
        "both); empty when none",
    )
    observed_median_minutes: float | None = Field(description="exp(mean of ln minutes)")
    estimate_minutes: float | None = Field(
        description="Posterior median: the planned duration as a prior of prior_strength "
        "observations, pooled with the observed ones on the log scale (log-normal)"
    )
    interval: tuple[float, float] | None = Field(
        description="90% interval of that median; null below two observations"
    )


class RobotEstimatesOut(BaseModel):
    robot: str
    prior_from_run: str | None = Field(description="The run whose configured rates are priors")
    reports: int = Field(description="Tasks reported done or failed on this robot")
    features: list[FeatureEstimateOut]
    durations: list[DurationOut]


class ReliabilityBinOut(BaseModel):
    low: float
    high: float
    reports: int
    predicted: float = Field(description="Mean success the plans expected of these tasks")
    observed: float = Field(description="Share of them reported done")


class SiteEstimatesOut(BaseModel):
    site: str
    as_of: Timestamp | None = Field(
        description="Reports the server received up to this time (null: all so far)"
    )
    computed_at: Timestamp
    prior_strength: float
    credible_level: float = 0.9
    reports: int
    robots: list[RobotEstimatesOut]
    reliability: list[ReliabilityBinOut] = Field(
        description="Predicted success against observed frequency, by tenth of predicted"
    )
