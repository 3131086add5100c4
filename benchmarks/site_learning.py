"""Learning from the site (SPEC 17, issue 23 item 6): a simulated site whose true success
rates differ from the configured ones, 30 days of the paper's 36 tasks, every outcome drawn
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
0.6; the site's heavy robot manages 0.3 there and the medium robot 0.35 (0.6 configured).
Underrated (the harder case): configured = the paper's rates with the heavy robot's careful at
0.3, but its careful work succeeds 0.9 of the time; a plan that never gives it careful work never
learns that, and `rates: "sampled"` (a Thompson draw per run) is measured as the way out.
And the read itself: the estimates of a site with 100,000 reports.
"""

from __future__ import annotations

import hashlib
import random
import statistics
import tempfile
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from fastapi.testclient import TestClient
from sklearn.calibration import calibration_curve
from sklearn.metrics import brier_score_loss, log_loss
from sqlalchemy import insert

from app.config import Settings
from app.domain.catalog import scenario
from app.domain.metrics import expected_success
from app.domain.models import Instance, Robot
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.serialize import instance_to_dict
from app.main import create_app
from app.solvers.registry import get_solver
from benchmarks import plots
from benchmarks.common import IMG, Section, table

DAYS = 30
SEEDS = (0, 1, 2, 3, 4)
MODE = Mode.BALANCED
Rates = dict[str, dict[str, float]]


def _rates(changes: Mapping[str, Mapping[str, float]], base: Rates | None = None) -> Rates:
    rates = base or {r.name: dict(r.success) for r in scenario("baseline").instance.robots}
    return {robot: {**fs, **changes.get(robot, {})} for robot, fs in rates.items()}


PAPER = _rates({})
CONFIGURED = _rates({"heavy": {"dexterous": 0.6}})
TRUE_RATES = _rates({"heavy": {"dexterous": 0.3}, "medium": {"dexterous": 0.35}}, CONFIGURED)
HARD_CONFIGURED = _rates({"heavy": {"careful": 0.3}}, PAPER)
HARD_TRUE = _rates({"heavy": {"careful": 0.9}}, PAPER)


@dataclass(frozen=True)
class Case:
    name: str
    configured: Rates
    true: Rates
    arms: tuple[str, ...]


CASES = (
    Case("overrated", CONFIGURED, TRUE_RATES, ("learned", "sampled")),
    Case("underrated", HARD_CONFIGURED, HARD_TRUE, ("learned", "sampled")),
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
    given: list[int] = field(default_factory=list)  # per day: tasks on the watched pair


@contextmanager
def served() -> Iterator[TestClient]:
    with tempfile.TemporaryDirectory(prefix="ltaa-sites-bench-") as tmp:
        settings = Settings(data_dir=Path(tmp), log_level="WARNING", max_concurrent_runs=2)
        with TestClient(create_app(settings)) as client:
            yield client


def _wait(client: TestClient, run_id: str) -> dict[str, Any]:
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        state: dict[str, Any] = client.get(f"/runs/{run_id}").json()
        if state["status"] == "completed":
            return state
        if state["status"] in ("failed", "cancelled"):
            raise RuntimeError(f"run {run_id} ended {state['status']}: {state['error']}")
        time.sleep(0.02)
    raise TimeoutError(f"run {run_id} did not complete")


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
    return _wait(client, created.json()["id"])


def planned_rates(client: TestClient, run_id: str, fallback: Rates) -> Rates:
    """The rates the run planned with, from its first event (configured: the request's)."""
    detail = client.get(f"/runs/{run_id}/trace").json()["events"][0]["detail"]
    if "learned" not in detail:
        return fallback
    return {
        robot: {f: r["used"] for f, r in fs.items()}
        for robot, fs in detail["learned"]["robots"].items()
    }


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
    return out


# -- the read at scale -------------------------------------------------------------------


def estimate_latency(reports: int = 100_000, repeats: int = 7) -> dict[str, float]:
    """Median seconds of GET /sites/{site}/estimates over a site with `reports` outcome rows
    (written as the reports would write them, in bulk), and of the service call alone."""
    from app.sites.service import site_estimates
    from app.store.site_models import SiteReport

    with served() as client:
        run = client.post(
            "/runs", json={"scenario": "baseline", "site": "big", "reasoner": "rules"}
        )
        run_id = run.json()["id"]
        _wait(client, run_id)
        sessions = client.app.state.runs.sessions  # type: ignore[attr-defined]
        rng = np.random.default_rng(0)
        robots = ["light", "medium", "heavy"]
        kinds = [
            ("Motion", '["dexterous"]'),
            ("ObjectInteraction", '["heavy"]'),
            ("Motion", '["careful", "heavy"]'),
            ("Audio", '["careful"]'),
        ]
        t0 = datetime(2026, 1, 1, tzinfo=UTC)
        rows = []
        for i in range(reports):
            kind, feats = kinds[i % len(kinds)]
            minutes = float(rng.lognormal(3.0, 0.4))
            p = float(rng.uniform(0.3, 0.95))
            rows.append(
                {
                    "site": "big",
                    "run_id": run_id,
                    "task_index": 1000 + i,
                    "task_id": str(i),
                    "robot": robots[i % 3],
                    "task_type": kind,
                    "features": feats,
                    "feature_set": hashlib.sha256(feats.encode()).hexdigest(),
                    "success": bool(rng.random() < p),
                    "predicted": p,
                    "predicted_bin": int(p * 10),
                    "reported_at": t0 + timedelta(minutes=i),
                    "received_at": t0 + timedelta(minutes=i),
                    "minutes": minutes,
                    "log_minutes": float(np.log(minutes)),
                    "planned_minutes": 20.0,
                }
            )
        with sessions.begin() as session:
            session.execute(insert(SiteReport), rows)
        api, service = [], []
        for _ in range(repeats):
            began = time.perf_counter()
            answer = client.get("/sites/big/estimates")
            api.append(time.perf_counter() - began)
            assert answer.json()["reports"] == reports
            began = time.perf_counter()
            site_estimates(sessions=sessions, site="big", strength=10.0)
            service.append(time.perf_counter() - began)
        as_of = (t0 + timedelta(minutes=reports // 2)).isoformat()
        began = time.perf_counter()
        half = client.get("/sites/big/estimates", params={"as_of": as_of}).json()
        half_s = time.perf_counter() - began
        assert half["reports"] == reports // 2 + 1
    return {
        "api": statistics.median(api),
        "service": statistics.median(service),
        "as_of": half_s,
    }


# -- the report --------------------------------------------------------------------------


def _mean_sd(values: Sequence[float]) -> str:
    sd = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{statistics.fmean(values):.2f} ± {sd:.2f}"


def _curve(arms: Sequence[Arm]) -> tuple[np.ndarray, np.ndarray]:
    data = np.array([a.regret for a in arms])
    return data.mean(axis=0), data.std(axis=0)


def figure(results: Mapping[str, Mapping[str, list[Arm]]], configured: Mapping[str, float]) -> str:
    fig, axes = plt.subplots(1, len(results), figsize=(12, 4.2), sharey=False)
    days = np.arange(1, DAYS + 1)
    for ax, (case, arms) in zip(axes, results.items(), strict=True):
        ax.axhline(configured[case], color=plots.PALETTE[0], label="configured")
        for i, (arm, runs) in enumerate(arms.items()):
            mean, sd = _curve(runs)
            colour = plots.PALETTE[i + 1]
            ax.plot(days, mean, color=colour, label=arm)
            ax.fill_between(days, mean - sd, mean + sd, color=colour, alpha=0.2)
        ax.axhline(0.5, color="#8C8C8C", linestyle=":", label="0.5-point target")
        ax.set_title(f"{case} rates")
        ax.set_xlabel("day")
        ax.set_ylabel("regret on the true rates (points)")
        ax.legend(fontsize=8)
    fig.suptitle("Learning from the site: regret per day (mean ± sd over seeds 0-4)")
    return plots.save(fig, "site_learning_regret.png", IMG)


def reliability_figure(arms: Sequence[Arm]) -> str:
    y = np.concatenate([a.y for a in arms])
    fig, ax = plt.subplots(figsize=(5, 5))
    ax.plot([0, 1], [0, 1], color="#8C8C8C", linestyle="--", label="calibrated")
    for i, (label, key) in enumerate((("configured", "p_configured"), ("learned", "p_learned"))):
        p = np.concatenate([getattr(a, key) for a in arms])
        observed, predicted = calibration_curve(y, p, n_bins=10)
        ax.plot(predicted, observed, marker="o", color=plots.PALETTE[i], label=label)
    ax.set_xlabel("predicted success")
    ax.set_ylabel("observed frequency")
    ax.set_title("Reliability (overrated case, learned arm)")
    ax.legend()
    return plots.save(fig, "site_learning_reliability.png", IMG)


def run() -> Section:
    results: dict[str, dict[str, list[Arm]]] = {}
    watch = {"overrated": ("heavy", "dexterous"), "underrated": ("heavy", "careful")}
    with served() as client:
        # The configured plan never changes (fixed rates, a deterministic planner): one day.
        configured = {
            case.name: simulate(client, case, "configured", 0, watch[case.name], days=1).regret[0]
            for case in CASES
        }
        for case in CASES:
            results[case.name] = {
                arm: [simulate(client, case, arm, seed, watch[case.name]) for seed in SEEDS]
                for arm in case.arms
            }
    latency = estimate_latency()
    regret_image = figure(results, configured)
    learned = results["overrated"]["learned"]
    reliability_image = reliability_figure(learned)

    rows = []
    for case in CASES:
        rows.append([case.name, "configured", *[f"{configured[case.name]:.2f}"] * 4, "-"])
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
            p_l = np.concatenate([a.p_learned for a in runs])
            p_c = np.concatenate([a.p_configured for a in runs])
            per_seed_l = [brier_score_loss(a.y, a.p_learned) for a in runs]
            per_seed_c = [brier_score_loss(a.y, a.p_configured) for a in runs]
            covered = sum(sum(a.covered) for a in runs) / max(
                1, sum(sum(a.intervals) for a in runs)
            )
            late = sum(sum(a.covered[10:]) for a in runs) / max(
                1, sum(sum(a.intervals[10:]) for a in runs)
            )
            scores.append(
                [
                    case.name,
                    arm,
                    f"{brier_score_loss(y, p_c):.4f}",
                    f"{brier_score_loss(y, p_l):.4f}",
                    f"{sum(lb < cb for lb, cb in zip(per_seed_l, per_seed_c, strict=True))}/5",
                    f"{log_loss(y, p_c, labels=[0, 1]):.4f}",
                    f"{log_loss(y, p_l, labels=[0, 1]):.4f}",
                    f"{covered:.1%}",
                    f"{late:.1%}",
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
    falling = statistics.fmean(a.regret[29] for a in over) <= day10
    hard = results["underrated"]["learned"]
    hard_given = sum(sum(a.given) for a in hard)
    sampled = results["underrated"]["sampled"]
    return (
        "A simulated site, 30 days of the paper's 36 tasks (`balanced`), seeds 0-4. Every "
        "day a durable run plans with `rates` configured, learned or sampled (rules reasoner "
        "with optimizer guidance: the exact optimum under the rates it plans with), each task's "
        "outcome is drawn from the site's true rates and reported through the API "
        "(`POST /runs/{id}/execution`, an in-process server), and the estimates are read back "
        "(`GET /sites/{site}/estimates`, prior strength 10). Regret: expected success on the "
        "true rates given away against the optimum on the true rates (`optimal` solver), in "
        "points; mean ± sd over the seeds.\n\n"
        "*Overrated*: configured = the paper's rates with the heavy robot's dexterous at 0.6; "
        "the site's heavy robot manages 0.3 there and the medium robot 0.35 (0.6 configured). "
        "*Underrated* (the harder case): configured = the paper's rates but the heavy robot's "
        "careful at 0.3; its careful work really succeeds 0.9 of the time.\n\n"
        + table(
            ["case", "rates", "day 1", "day 5", "day 10", "day 30", "tasks on the watched pair"],
            rows,
        )
        + f"\n\n![Regret per day]({regret_image})\n\n"
        "Prequential scores (each day's outcomes predicted before they are reported; "
        "scikit-learn's `brier_score_loss`, `log_loss`), and how often the 90% intervals "
        "of every (robot, feature) with a report held the true rate (all days; days 11-30):\n\n"
        + table(
            [
                "case",
                "arm",
                "Brier configured",
                "Brier learned",
                "seeds learned better",
                "log loss configured",
                "log loss learned",
                "coverage",
                "coverage days 11-30",
            ],
            scores,
        )
        + f"\n\n![Reliability]({reliability_image})\n\n"
        f"**Targets.** Learned-rate regret on day 10: {day10:.2f} points (target at most 0.5), "
        f"{'falling or flat' if falling else 'not falling'} to day 30; configured stays at "
        f"{configured['overrated']:.2f}. "
        f"**The harder case:** with learned rates the heavy robot was given "
        f"{hard_given} careful task(s) in {len(hard) * DAYS} days: a plan that never gives it "
        "the work never learns it, and its regret stays where the configured plan's is. "
        f"Sampled rates (a Thompson draw per run, recorded in its first event) gave it "
        f"{sum(sum(a.given) for a in sampled)} and end at "
        f"{statistics.fmean(a.regret[29] for a in sampled):.2f} points on day 30 "
        f"(mean of days 21-30: {statistics.fmean(np.mean(a.regret[20:]) for a in sampled):.2f}), "
        "the price of exploring being the regret of the days it tries.\n\n"
        f"**The read at scale:** the estimates of a site with 100,000 reports take "
        f"{latency['api'] * 1000:.0f} ms through `GET /sites/{{site}}/estimates` "
        f"({latency['service'] * 1000:.0f} ms in the service; one grouped scan of the outcome "
        f"table), {latency['as_of'] * 1000:.0f} ms with an `as_of` halfway (SQLite, median of 7).\n"
    )


if __name__ == "__main__":
    print(run().body)
