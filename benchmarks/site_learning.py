"""Learning from the site (docs/estimates.md#sites, issue 23 item 6): a simulated site whose true
success rates differ from the configured ones, 30 days of the paper's 36 tasks, every outcome drawn
from the true rates and reported through the API (an in-process server: POST /runs, POST
/runs/{id}/execution, GET /sites/{site}/estimates).

Each day a durable run plans the queue (rules reasoner with optimizer guidance: the exact
optimum under the rates it plans with) with `rates: "configured"`, `"learned"` or
`"sampled"`; its plan is scored on the true rates against the optimum on the true rates
(the `optimal` solver): the regret, in points of expected success. Before the day's outcomes
are reported, the learned rates predict each task (prequential: predict, then update); the
Brier score, log loss and reliability come from scikit-learn. After the reports, each
(robot, feature) with a report has its 90% interval checked against the true rate.

Two cases. Overrated: configured = the paper's rates with the heavy robot's dexterous at
0.65 (0.6 would tie the medium robot); the site's heavy robot manages 0.3 there.
Underrated (the harder case): configured = the paper's rates with the heavy robot's careful at
0.3, but its careful work succeeds 0.9 of the time; a plan that never gives it careful work never
learns that, and `rates: "sampled"` (a Thompson draw per run) is measured as the way out.
And the read itself: the estimates of a site with 100,000 reports.
"""

from __future__ import annotations

import random
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from fastapi.testclient import TestClient
from sklearn.calibration import calibration_curve
from sklearn.metrics import brier_score_loss, log_loss

from app.domain.catalog import scenario
from app.domain.metrics import expected_success
from app.domain.models import Instance, Robot
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.serialize import instance_to_dict
from app.solvers.registry import get_solver
from benchmarks import plots
from benchmarks.common import IMG, Section, table
from benchmarks.site_scale import estimate_latency, served, wait

DAYS = 30
SEEDS = (0, 1, 2, 3, 4)
MODE = Mode.BALANCED
Rates = dict[str, dict[str, float]]


def _rates(changes: Mapping[str, Mapping[str, float]], base: Rates | None = None) -> Rates:
    rates = base or {r.name: dict(r.success) for r in scenario("baseline").instance.robots}
    return {robot: {**fs, **changes.get(robot, {})} for robot, fs in rates.items()}


PAPER = _rates({})
# 0.65, not 0.6: at 0.6 the heavy robot would tie the medium robot's dexterous 0.6, and
# whether the configured plan gives it dexterous work would be left to tie-breaking.
CONFIGURED = _rates({"heavy": {"dexterous": 0.65}})
TRUE_RATES = _rates({"heavy": {"dexterous": 0.3}}, CONFIGURED)
HARD_CONFIGURED = _rates({"heavy": {"careful": 0.3}}, PAPER)
HARD_TRUE = _rates({"heavy": {"careful": 0.9}}, PAPER)


@dataclass(frozen=True)
class Case:
    name: str
    configured: Rates
    true: Rates
    arms: tuple[str, ...]


CASES = (
    Case("overrated", CONFIGURED, TRUE_RATES, ("configured", "learned", "sampled")),
    Case("underrated", HARD_CONFIGURED, HARD_TRUE, ("configured", "learned", "sampled")),
)


def instance_with(rates: Rates) -> Instance:
    base = scenario("baseline").instance
    robots = tuple(Robot(r.name, rates[r.name], r.label, r.description) for r in base.robots)
    return Instance(base.tasks, robots)


def success(rates: Rates, robot: str, features: Sequence[str]) -> float:
    return sum(rates[robot][f] for f in features) / len(features)


@dataclass
class Arm:
    """One arm of one case over the days of one seed."""

    regret: list[float] = field(default_factory=list)  # points, per day
    y: list[int] = field(default_factory=list)  # outcomes, in report order
    p_learned: list[float] = field(default_factory=list)  # predicted before the report
    p_configured: list[float] = field(default_factory=list)
    covered: list[int] = field(default_factory=list)  # per day: intervals holding the truth
    intervals: list[int] = field(default_factory=list)  # per day: intervals checked
    # per day: intervals holding the rate the counts measure (the mean true S of the tasks
    # counted for the pair: a two-feature task's outcome counts for both features)
    measured: list[int] = field(default_factory=list)
    given: list[int] = field(default_factory=list)  # per day: tasks on the watched pair


def plan(client: TestClient, case: Case, site: str, rates: str, seed: int) -> dict[str, Any]:
    body = {
        **instance_to_dict(instance_with(case.configured)),
        "mode": MODE.value,
        "reasoner": "rules",
        "guidance": "optimizer",
        "site": site,
        "rates": rates,
        "seed": seed,
    }
    created = client.post("/runs", json=body)
    created.raise_for_status()
    return wait(client, created.json()["id"])


def posterior_means(client: TestClient, site: str) -> tuple[Rates, dict[tuple[str, str], Any]]:
    body = client.get(f"/sites/{site}/estimates").json()
    means: Rates = {}
    rows: dict[tuple[str, str], Any] = {}
    for robot in body["robots"]:
        for f in robot["features"]:
            means.setdefault(robot["robot"], {})[f["feature"]] = f["posterior_mean"]
            rows[(robot["robot"], f["feature"])] = f
    return means, rows


def simulate(
    client: TestClient, case: Case, arm: str, seed: int, watch: tuple[str, str], days: int = DAYS
) -> Arm:
    features = {str(t.id): list(t.features) for t in scenario("baseline").instance.tasks}
    true_instance = instance_with(case.true)
    optimum = expected_success(
        true_instance, get_solver("optimal").solve(Problem.build(true_instance, MODE)).assignment
    )
    names = [r.name for r in true_instance.robots]
    rng = random.Random(f"{case.name}/{arm}/{seed}")
    site = f"{case.name}-{arm}-{seed}"
    out = Arm()
    start = datetime(2026, 12, 1, 7, tzinfo=UTC)
    counted: dict[tuple[str, str], list[float]] = {}  # pair -> [sum of true S, reports]
    for day in range(days):
        run = plan(client, case, site, arm, seed=seed * 1000 + day)
        if day == 0:
            believed = case.configured  # nothing reported yet: the prior
        else:
            believed, _ = posterior_means(client, site)
        assignment = [names.index(a["robot"]) for a in run["assignments"]]
        out.regret.append(100 * (optimum - expected_success(true_instance, assignment)))
        updates = []
        watched = 0
        for i, a in enumerate(run["assignments"]):
            need = features[str(a["task_id"])]
            done = rng.random() < success(case.true, a["robot"], need)
            out.y.append(int(done))
            out.p_learned.append(success(believed, a["robot"], need))
            out.p_configured.append(success(case.configured, a["robot"], need))
            watched += a["robot"] == watch[0] and watch[1] in need
            for f in need:
                pair = counted.setdefault((a["robot"], f), [0.0, 0])
                pair[0] += success(case.true, a["robot"], need)
                pair[1] += 1
            at = (start + timedelta(days=day, minutes=10 * i)).isoformat()
            updates.append(
                {"task_id": a["task_id"], "state": "done" if done else "failed", "at": at}
            )
        out.given.append(watched)
        client.post(f"/runs/{run['id']}/execution", json={"updates": updates}).raise_for_status()
        _, rows = posterior_means(client, site)
        checked = [
            (r["interval"][0] <= case.true[robot][f] <= r["interval"][1])
            for (robot, f), r in rows.items()
            if r["successes"] + r["failures"] > 0
        ]
        out.covered.append(sum(checked))
        out.intervals.append(len(checked))
        out.measured.append(
            sum(
                r["interval"][0] <= counted[key][0] / counted[key][1] <= r["interval"][1]
                for key, r in rows.items()
                if r["successes"] + r["failures"] > 0
            )
        )
    return out


# -- the report --------------------------------------------------------------------------


def _mean_sd(values: Sequence[float]) -> str:
    sd = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{statistics.fmean(values):.2f} ± {sd:.2f}"


def _curve(arms: Sequence[Arm]) -> tuple[np.ndarray, np.ndarray]:
    data = np.array([a.regret for a in arms])
    return data.mean(axis=0), data.std(axis=0)


def figure(results: Mapping[str, Mapping[str, list[Arm]]]) -> str:
    fig, axes = plt.subplots(1, len(results), figsize=(12, 4.2), sharey=False)
    days = np.arange(1, DAYS + 1)
    for ax, (case, arms) in zip(axes, results.items(), strict=True):
        for i, (arm, runs) in enumerate(arms.items()):
            mean, sd = _curve(runs)
            colour = plots.PALETTE[i]
            ax.plot(days, mean, color=colour, label=arm)
            ax.fill_between(days, mean - sd, mean + sd, color=colour, alpha=0.2)
        ax.axhline(0.5, color="#8C8C8C", linestyle=":", label="0.5-point target")
        ax.set_title(f"{case} rates")
        ax.set_xlabel("day")
        ax.set_ylabel("regret on the true rates (points)")
        ax.legend(fontsize=8)
    fig.suptitle("Learning from the site: regret per day (mean ± sd over seeds 0-4)")
    return plots.save(fig, "site_learning_regret.png", IMG)


def own(arm: str, a: Arm) -> list[float]:
    """What the arm's plans predicted: configured rates, or the posterior means."""
    return a.p_configured if arm == "configured" else a.p_learned


def reliability_figure(arms: Mapping[str, list[Arm]]) -> str:
    fig, ax = plt.subplots(figsize=(5, 5))
    ax.plot([0, 1], [0, 1], color="#8C8C8C", linestyle="--", label="calibrated")
    for i, name in enumerate(("configured", "learned")):
        y = np.concatenate([a.y for a in arms[name]])
        p = np.concatenate([own(name, a) for a in arms[name]])
        observed, predicted = calibration_curve(y, p, n_bins=10)
        ax.plot(predicted, observed, marker="o", color=plots.PALETTE[i], label=f"{name} rates")
    ax.set_xlabel("predicted success")
    ax.set_ylabel("observed frequency")
    ax.set_title("Reliability, overrated case (each arm's own plans)")
    ax.legend()
    return plots.save(fig, "site_learning_reliability.png", IMG)


def run() -> Section:
    results: dict[str, dict[str, list[Arm]]] = {}
    watch = {"overrated": ("heavy", "dexterous"), "underrated": ("heavy", "careful")}
    with served() as client:
        for case in CASES:
            results[case.name] = {
                arm: [simulate(client, case, arm, seed, watch[case.name]) for seed in SEEDS]
                for arm in case.arms
            }
    latency = estimate_latency()  # benchmarks.site_scale
    configured = {
        name: statistics.fmean(np.mean(a.regret) for a in arms["configured"])
        for name, arms in results.items()
    }
    regret_image = figure(results)
    reliability_image = reliability_figure(results["overrated"])

    rows = []
    for case in CASES:
        for arm, runs in results[case.name].items():
            given = statistics.fmean(sum(a.given) for a in runs)
            rows.append(
                [
                    case.name,
                    arm,
                    _mean_sd([a.regret[0] for a in runs]),
                    _mean_sd([a.regret[4] for a in runs]),
                    _mean_sd([a.regret[9] for a in runs]),
                    _mean_sd([a.regret[29] for a in runs]),
                    f"{given:.0f}",
                ]
            )
    scores = []
    for case in CASES:
        for arm, runs in results[case.name].items():
            y = np.concatenate([a.y for a in runs])
            p = np.concatenate([own(arm, a) for a in runs])
            p_c = np.concatenate([a.p_configured for a in runs])
            seeds = [brier_score_loss(a.y, own(arm, a)) for a in runs]
            checked = max(1, sum(sum(a.intervals) for a in runs))
            late = max(1, sum(sum(a.intervals[10:]) for a in runs))
            scores.append(
                [
                    case.name,
                    arm,
                    f"{brier_score_loss(y, p):.4f} ± {statistics.stdev(seeds):.4f}",
                    f"{log_loss(y, p, labels=[0, 1]):.4f}",
                    f"{brier_score_loss(y, p_c):.4f}",
                    f"{sum(sum(a.covered) for a in runs) / checked:.1%}",
                    f"{sum(sum(a.covered[10:]) for a in runs) / late:.1%}",
                    f"{sum(sum(a.measured) for a in runs) / checked:.1%}",
                ]
            )
    body = _report(rows, scores, latency, regret_image, reliability_image, results, configured)
    return Section("Learning from the site: estimates from execution reports", body, [regret_image])


def _report(
    rows: list[list[str]],
    scores: list[list[str]],
    latency: Mapping[str, float],
    regret_image: str,
    reliability_image: str,
    results: Mapping[str, Mapping[str, list[Arm]]],
    configured: Mapping[str, float],
) -> str:
    over = results["overrated"]["learned"]
    day10 = statistics.fmean(a.regret[9] for a in over)
    day30 = statistics.fmean(a.regret[29] for a in over)
    hard = results["underrated"]["learned"]
    sampled = results["underrated"]["sampled"]
    idle = sum(1 for a in hard for g in a.given if g == 0)
    never = sum(1 for a in hard if sum(a.given[1:]) == 0)
    late_learned = statistics.fmean(np.mean(a.regret[20:]) for a in hard)
    late_sampled = statistics.fmean(np.mean(a.regret[20:]) for a in sampled)
    return (
        "A simulated site, 30 days of the paper's 36 tasks (`balanced`), seeds 0-4. Every "
        "day a durable run plans with `rates` configured, learned or sampled (rules reasoner "
        "with optimizer guidance: the exact optimum under the rates it plans with), each task's "
        "outcome is drawn from the site's true rates and reported through the API "
        "(`POST /runs/{id}/execution`, an in-process server), and the estimates are read back "
        "(`GET /sites/{site}/estimates`, prior strength 10). Regret: expected success on the "
        "true rates given away against the optimum on the true rates (`optimal` solver), in "
        "points; mean ± sd over the seeds.\n\n"
        "*Overrated*: configured = the paper's rates with the heavy robot's dexterous at 0.65 "
        "(0.6 would tie the medium robot's 0.6 and leave the configured plan to tie-breaking); "
        "the site's heavy robot manages 0.3 there. "
        "*Underrated* (the harder case): configured = the paper's rates but the heavy robot's "
        "careful at 0.3; its careful work really succeeds 0.9 of the time.\n\n"
        + table(
            [
                "case",
                "rates",
                "day 1",
                "day 5",
                "day 10",
                "day 30",
                "tasks on the watched pair, per seed",
            ],
            rows,
        )
        + f"\n\n![Regret per day]({regret_image})\n\n"
        "Prequential scores: each day's outcomes predicted before they are reported, by the "
        "rates that day's plan used (configured, or the posterior means; for sampled plans the "
        "posterior means, not the draw), with scikit-learn's `brier_score_loss` and `log_loss` "
        "(mean over all reports; ± the sd of the per-seed scores); beside it the configured "
        "rates scored on the same outcomes. Then how often the 90% interval of every (robot, "
        "feature) with a report held the true rate, read after each day's reports (every "
        "site's estimates are read from the API, prior strength 10):\n\n"
        + table(
            [
                "case",
                "rates",
                "Brier (its plans' predictions)",
                "log loss",
                "Brier of the configured rates on the same outcomes",
                "90% intervals holding the true rate",
                "same, days 11-30",
                "holding the rate the counts measure",
            ],
            scores,
        )
        + f"\n\n![Reliability]({reliability_image})\n\n"
        f"**Targets.** Learned-rate regret on day 10: {day10:.2f} points (target at most 0.5: "
        f"{'met' if day10 <= 0.5 else 'missed'}), {day30:.2f} on day 30; configured stays at "
        f"{configured['overrated']:.2f} every day. Brier score and coverage: the table above; "
        "where the coverage of the true rate falls short while the coverage of the counted "
        "rate holds, the shortfall is the counting rule of docs/estimates.md#the-model "
        "(a two-feature task's outcome "
        "counts for both features, so a feature's count mixes in its partner's rate), not the "
        "intervals.\n\n"
        f"**The harder case.** With learned rates the heavy robot was given no careful task on "
        f"{idle} of {len(hard) * DAYS} days; in {never} of {len(hard)} seeds never after day 1 "
        "(a plan that does not give it the work does not learn it, unless other estimates move "
        "enough to hand it some). Its regret over days 21-30 averages "
        f"{late_learned:.2f} points (configured: {configured['underrated']:.2f}). Sampled "
        'rates (`rates: "sampled"`, a Thompson draw from each posterior per run, recorded in '
        f"its first event) gave it {sum(sum(a.given) for a in sampled)} careful tasks against "
        f"{sum(sum(a.given) for a in hard)} and average {late_sampled:.2f} points over days "
        "21-30: exploring costs regret on the days a draw is wrong.\n\n"
        f"**The read at scale:** the estimates of a site with 100,000 reports take "
        f"{latency['api'] * 1000:.0f} ms through `GET /sites/{{site}}/estimates` "
        f"({latency['service'] * 1000:.0f} ms in the service; one grouped scan of the outcome "
        f"table), {latency['as_of'] * 1000:.0f} ms with an `as_of` halfway (SQLite, median of 7).\n"
    )


if __name__ == "__main__":
    print(run().body)
