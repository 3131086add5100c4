"""The Bayesian arithmetic of docs/estimates.md#the-model (app.domain.estimates), against scipy and
by hand."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from app.domain.estimates import (
    Basis,
    BetaEstimate,
    Counts,
    DurationEstimate,
    LogStats,
    RateSource,
    configured_rates,
    plan_durations,
    plan_rates,
    rate_notes,
    rates_record,
    with_rates,
)
from app.graph.prompts import TARGET_USER_PROMPT_CHARS, user_prompt
from tests.support.ltaa_support import context

ROBOTS = [
    {"name": "light", "success": {"heavy": 0.5, "careful": 0.9}},
    {"name": "heavy", "success": {"heavy": 0.9, "careful": 0.5}},
]


def test_the_posterior_is_the_prior_mean_weighted_as_pseudo_observations() -> None:
    e = BetaEstimate(prior=0.6, strength=10, successes=3, failures=7)
    assert (e.alpha, e.beta) == pytest.approx((9.0, 11.0))
    assert e.mean == pytest.approx(9 / 20)
    low, high = e.interval
    assert (low, high) == pytest.approx(tuple(stats.beta.ppf([0.05, 0.95], 9, 11)))
    assert BetaEstimate(0.6, 10, 0, 0).mean == pytest.approx(0.6)  # nothing seen: the prior
    # A configured certainty is a point mass until something contradicts it.
    assert BetaEstimate(1.0, 10, 4, 0).interval == (1.0, 1.0)
    assert BetaEstimate(1.0, 10, 4, 1).mean == pytest.approx(14 / 15)


def test_learned_rates_fall_back_to_the_prior_and_say_so() -> None:
    counts = {("heavy", "careful"): Counts(1, 9)}
    planned = plan_rates(ROBOTS, counts, source=RateSource.LEARNED, strength=10)
    assert planned["heavy"]["careful"].used == pytest.approx((5 + 1) / 20)
    assert planned["heavy"]["careful"].basis == Basis.LEARNED
    assert planned["heavy"]["heavy"].basis == Basis.PRIOR
    assert planned["heavy"]["heavy"].used == 0.9
    only = plan_rates(ROBOTS, counts, source=RateSource.LEARNED, strength=10, only={"light"})
    assert only["heavy"]["careful"].basis == Basis.CONFIGURED
    record = rates_record(
        planned,
        source=RateSource.LEARNED,
        site="s1",
        as_of="t",
        strength=10,
        needed={"careful"},
    )
    assert record["fallback"] == [{"robot": "light", "feature": "careful"}]  # needed only
    robots = with_rates(ROBOTS, planned)
    assert robots[1]["success"]["careful"] == pytest.approx(0.3)
    # The configured rates survive in the record, for the next revision and the site view.
    assert configured_rates(robots, record) == ROBOTS
    assert rate_notes(record) == {
        "light": {"heavy": ("prior", 0), "careful": ("prior", 0)},
        "heavy": {"heavy": ("prior", 0), "careful": ("learned", 10)},
    }


def test_a_sampled_rate_is_a_seeded_draw_from_the_posterior() -> None:
    counts = {("heavy", "careful"): Counts(30, 70)}

    def draw(seed: int) -> float:
        planned = plan_rates(
            ROBOTS,
            counts,
            source=RateSource.SAMPLED,
            strength=10,
            rng=np.random.default_rng(seed),
        )
        assert planned["heavy"]["careful"].basis == Basis.SAMPLED
        return planned["heavy"]["careful"].used

    assert draw(1) == draw(1) != draw(2)
    draws = [draw(s) for s in range(200)]
    assert abs(np.mean(draws) - 35 / 110) < 0.02  # the posterior mean


def test_durations_are_log_normal_pooled_with_the_plan() -> None:
    seen = LogStats.of([20.0, 40.0, 80.0])
    assert seen.mean_log == pytest.approx(math.log(40.0))
    untimed = DurationEstimate(None, seen, strength=10)
    assert untimed.median == pytest.approx(40.0) and untimed.observed_median == pytest.approx(40)
    timed = DurationEstimate(30.0, seen, strength=10)
    expected = math.exp((10 * math.log(30) + 3 * math.log(40)) / 13)
    assert timed.median == pytest.approx(expected)
    low, high = timed.interval or (0.0, 0.0)
    assert low < expected < high
    assert DurationEstimate(30.0, LogStats.of([50.0]), 10).interval is None


def test_learned_durations_go_into_timed_tasks_only() -> None:
    tasks = [
        {"id": 1, "type": "Weld", "features": ["heavy"], "duration": 30},
        {"id": 2, "type": "Lift", "features": ["heavy"], "duration": {"heavy": 10}},
    ]
    observed = {("heavy", "Weld"): LogStats.of([60.0] * 10)}
    out, record = plan_durations(tasks, ["light", "heavy"], observed, strength=10)
    assert out[0]["duration"]["light"] == 30.0  # nothing seen: the plan
    assert out[0]["duration"]["heavy"] == pytest.approx(math.sqrt(30 * 60), abs=1e-3)
    assert out[1]["duration"] == {"heavy": 10.0}
    assert record["applied"] is True
    untimed, said = plan_durations([{"id": 1, "features": ["heavy"]}], ["heavy"], {}, strength=10)
    assert untimed == [{"id": 1, "features": ["heavy"]}] and said["applied"] is False


def test_the_prompt_says_which_rates_are_learned_and_stays_compact() -> None:
    notes = ("", "heavy configured, no reports yet", "heavy learned on 37 reports")
    text = user_prompt(replace(context(), rate_notes=notes))
    assert "Heavy Robot [heavy]: S 90.0% (heavy learned on 37 reports), load 6" in text
    assert "Light Robot [light]: S 50.0%, load 3" in text
    assert "posterior means from this site's reports" in text
    assert len(text) <= TARGET_USER_PROMPT_CHARS
    assert "posterior" not in user_prompt(context())  # configured runs: the prompt as before
