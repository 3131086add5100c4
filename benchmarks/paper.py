"""The paper's experiments on our data (issue 4): methods comparison (Fig. 15), scenarios
(Fig. 16), modes (Fig. 17), workload and feature success (Figs. 18-19), the exact
success/balance frontier with every method on it, and Claude's cost when a key exists.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass
from typing import Any

from app.config import get_settings
from app.domain.catalog import scenario, scenarios
from app.domain.metrics import balance_score, compute_metrics
from app.domain.models import Instance
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.reasoners.factory import resolve_api_key
from app.solvers.registry import get_solver
from benchmarks import plots
from benchmarks.cache import GUIDED, SIMULATION_TRIALS, Solved, solved
from benchmarks.common import Section, fmt_time, table
from benchmarks.solvers import LEARNER_SEEDS, LEARNERS

PAPER_LTAA_ES, PAPER_LTAA_LOADS = 0.76, (22, 10, 4)  # reported by the paper
CLAUDE_TASKS = 6


@dataclass(frozen=True)
class Method:
    key: str  # unique id
    label: str
    solver: str
    options: dict[str, Any] | None = None


METHODS = (
    Method("greedy", "Greedy", "greedy"),
    Method("dp", "DP (exact)", "dp"),
    Method("optimal", "Optimal (min-cost flow)", "optimal"),
    Method("q_learning", "Q-learning", "q_learning"),
    Method("dqn", "DQN", "dqn"),
    Method("ltaa", "LTAA (rules)", "ltaa"),
    Method("ltaa_guided", "LTAA + optimizer guidance", "ltaa", GUIDED),
)
BY_KEY = {m.key: m for m in METHODS}
# Figs. 16-17 leave out dp (equal to optimal) and DQN (a 20-40 s training per cell would
# dominate the bench; DQN is measured over five seeds on baseline/balanced instead).
GRID_METHODS = ("greedy", "optimal", "q_learning", "ltaa", "ltaa_guided")
RL_NOTE = (
    "Q-learning: seed 0; DQN is left out here (one 25-60 s training per cell), see the "
    "learners section for both over five seeds"
)


def result(key: str, sc: str = "baseline", mode: str = "balanced", seed: int = 0) -> Solved:
    m = BY_KEY[key]
    return solved(m.solver, sc, mode, seed=seed, options=m.options)


def _pct(x: float) -> float:
    return x * 100


def method_point(m: Method) -> plots.MethodPoint:
    if m.solver not in LEARNERS:
        r = result(m.key)
        c = r.metrics.simulated_completion
        return plots.MethodPoint(
            m.label,
            _pct(r.metrics.expected_success),
            None,
            _pct(c.mean),
            (_pct(c.ci95[0]), _pct(c.ci95[1])),
        )
    runs = [result(m.key, seed=s) for s in LEARNER_SEEDS]
    es = [_pct(r.metrics.expected_success) for r in runs]
    means = [_pct(r.metrics.simulated_completion.mean) for r in runs]
    # The mean of n independent estimates: its half-width is the root-sum-square / n.
    halves = [
        _pct(r.metrics.simulated_completion.ci95[1] - r.metrics.simulated_completion.ci95[0]) / 2
        for r in runs
    ]
    half = math.sqrt(sum(h * h for h in halves)) / len(halves)
    mean = statistics.fmean(means)
    return plots.MethodPoint(
        f"{m.label} ({len(runs)} seeds)",
        statistics.fmean(es),
        (min(es), max(es)),
        mean,
        (mean - half, mean + half),
    )


def methods_part() -> tuple[str, str]:
    points = [method_point(m) for m in METHODS]
    caption = (
        "Baseline scenario (36 TEACh tasks x 3 robots), balanced mode (cap 4). Each allocation "
        f"simulated {SIMULATION_TRIALS:,} times (seed 0, common random numbers). Q-learning and "
        f"DQN: mean over seeds {LEARNER_SEEDS[0]}-{LEARNER_SEEDS[-1]}, expected-success whiskers "
        "min-max over seeds, completion interval of the mean of the five. brute_force refuses "
        "3^36 assignments."
    )
    image = plots.methods_figure(
        points, "Methods comparison (paper Fig. 15)", caption, "methods.png"
    )
    rows = []
    for m in METHODS:
        r = result(m.key)
        c = r.metrics.simulated_completion
        rows.append(
            [
                m.label,
                f"{_pct(r.metrics.expected_success):.2f}%",
                f"{r.metrics.balance_score:.1f}",
                "/".join(str(v) for v in r.metrics.workload.values()),
                f"{r.metrics.jain_index:.3f}",
                f"{_pct(c.mean):.2f}% [{_pct(c.ci95[0]):.2f}, {_pct(c.ci95[1]):.2f}]",
            ]
        )
    text = (
        f"{caption} The table shows seed 0 for the learners; the figure their five-seed "
        "mean.\n\n"
        + table(
            [
                "method",
                "expected success",
                "balance",
                "workload L/M/H",
                "Jain",
                "simulated completion [95% interval]",
            ],
            rows,
        )
        + f"\n\n![Methods comparison]({image})\n"
    )
    return text, image


def _zoom(series: dict[str, list[float]]) -> tuple[float, float]:
    """A percentage axis cut to the data (5-point steps), so small gaps stay visible."""
    values = [v for vs in series.values() for v in vs]
    return (5 * math.floor(min(values) / 5) - 5, min(100, 5 * math.ceil(max(values) / 5) + 5))


def _grid_panels(cells: list[tuple[str, str]], labels: list[str]) -> list[plots.Panel]:
    es: dict[str, list[float]] = {}
    balance: dict[str, list[float]] = {}
    for key in GRID_METHODS:
        rs = [result(key, sc, mode) for sc, mode in cells]
        es[BY_KEY[key].label] = [_pct(r.metrics.expected_success) for r in rs]
        balance[BY_KEY[key].label] = [r.metrics.balance_score for r in rs]
    return [
        plots.Panel(labels, es, "expected success (%)", _zoom(es)),
        plots.Panel(labels, balance, "balance score (0-100)", (0, 105)),
    ]


def _grid_table(cells: list[tuple[str, str]]) -> str:
    rows = []
    for sc, mode in cells:
        for key in GRID_METHODS:
            r = result(key, sc, mode)
            rows.append(
                [
                    sc,
                    mode,
                    BY_KEY[key].label,
                    f"{_pct(r.metrics.expected_success):.2f}%",
                    f"{r.metrics.balance_score:.1f}",
                    "/".join(str(v) for v in r.metrics.workload.values()),
                ]
            )
    return table(
        ["scenario", "mode", "method", "expected success", "balance", "workload L/M/H"], rows
    )


def scenarios_part() -> tuple[str, str]:
    names = list(scenarios())
    cells = [(sc, "balanced") for sc in names]
    caption = (
        f"Each scenario's 36 TEACh tasks x 3 robots, balanced mode (cap 4), seed 0. "
        f"{RL_NOTE}. Expected-success axis does not start at 0."
    )
    image = plots.panels_figure(
        _grid_panels(cells, names), "The four scenarios (paper Fig. 16)", caption, "scenarios.png"
    )
    return (
        f"{caption}\n\n![Scenarios]({image})\n\n<details><summary>Numbers</summary>\n\n"
        f"{_grid_table(cells)}\n\n</details>\n"
    ), image


def modes_part() -> tuple[str, str]:
    cells = [("baseline", mode.value) for mode in Mode]
    caps = [result("optimal", "baseline", mode.value).max_deviation for mode in Mode]
    labels = [
        f"{mode.value}\n(cap {'none' if c is None else f'{c:g}'})"
        for mode, c in zip(Mode, caps, strict=True)
    ]
    zero = [
        mode.value
        for mode in Mode
        if all(result(k, "baseline", mode.value).metrics.balance_score == 0 for k in GRID_METHODS)
    ]
    note = (
        f" Balance 0 in {', '.join(zero)}: without a cap every method leaves a robot 12 "
        "or more tasks off the target of 12."
        if zero
        else ""
    )
    caption = (
        f"Baseline scenario, 36 tasks x 3 robots, each mode with its default cap, seed "
        f"0. {RL_NOTE}. Expected-success axis does not start at 0.{note}"
    )
    image = plots.panels_figure(
        _grid_panels(cells, labels),
        "The three operational modes (paper Fig. 17)",
        caption,
        "modes.png",
    )
    return (
        f"{caption}\n\n![Modes]({image})\n\n<details><summary>Numbers</summary>\n\n"
        f"{_grid_table(cells)}\n\n</details>\n"
    ), image


def distribution_part() -> tuple[str, list[str]]:
    inst = scenario("baseline").instance
    keys = [m.key for m in METHODS if m.key != "dp"]
    labels = [BY_KEY[k].label.replace(" + ", "\n+ ") for k in keys]
    rs = [result(k) for k in keys]
    cap = rs[0].max_deviation or 0
    w = inst.target_load
    loads = {robot.display: [r.metrics.workload[robot.name] for r in rs] for robot in inst.robots}
    caption = (
        "Baseline scenario, 36 tasks x 3 robots, balanced mode (cap 4: loads in [8, 16]), "
        "seed 0 for every method including the learners; dp equals optimal and is "
        "left out."
    )
    workload = plots.panels_figure(
        [
            plots.Panel(
                labels,
                loads,
                "tasks assigned",
                (0, max(map(max, loads.values())) + 4),
                {f"target W = {w:g}": w},
                (w - cap, w + cap),
            )
        ],
        "Workload distribution per method (paper Fig. 18)",
        caption,
        "workload.png",
        width=12.5,
    )
    features = list(inst.features)
    per_method = {
        BY_KEY[k].label: [_pct(r.metrics.feature_success[f]) for f in features]
        for k, r in zip(keys, rs, strict=True)
    }
    feature_img = plots.panels_figure(
        [
            plots.Panel(
                features, per_method, "mean success of tasks needing it (%)", _zoom(per_method)
            )
        ],
        "Success per feature (paper Fig. 19)",
        caption + " Axis does not start at 0.",
        "features.png",
        width=11,
    )
    rows = [[label, *(f"{v:.2f}%" for v in values)] for label, values in per_method.items()]
    text = (
        f"{caption}\n\n![Workload distribution]({workload})\n\n"
        f"![Feature success]({feature_img})\n\n<details><summary>Feature success"
        "</summary>\n\n" + table(["method", *features], rows) + "\n\n</details>\n"
    )
    return text, [workload, feature_img]


def frontier_points() -> list[tuple[str, float, float]]:
    """The optimum at every integer cap from 0 up to the uncapped optimum's deviation."""
    inst = scenario("baseline").instance
    out = []
    for k in range(0, math.ceil(inst.target_load) + 1):
        m = solved("optimal", "baseline", "success_focused", max_deviation=k).metrics
        out.append((f"cap {k}", m.balance_score, _pct(m.expected_success)))
    m = solved("optimal", "baseline", "success_focused").metrics
    out.append(("no cap", m.balance_score, _pct(m.expected_success)))
    return out


def frontier_part() -> tuple[str, str]:
    inst = scenario("baseline").instance
    frontier = frontier_points()
    markers = "os^vDPX*ph"
    placed = []
    for i, m in enumerate(METHODS):
        r = result(m.key)
        placed.append(
            plots.PlacedPoint(
                f"{m.label}, balanced",
                r.metrics.balance_score,
                _pct(r.metrics.expected_success),
                markers[i],
            )
        )
    for mode in ("success_focused", "aggressive_balance"):
        r = result("ltaa", "baseline", mode)
        placed.append(
            plots.PlacedPoint(
                f"LTAA (rules), {mode}",
                r.metrics.balance_score,
                _pct(r.metrics.expected_success),
                "h",
            )
        )
    paper_b = balance_score(PAPER_LTAA_LOADS, inst.target_load)
    placed.append(
        plots.PlacedPoint("paper's LTAA (reported, 22/10/4)", paper_b, _pct(PAPER_LTAA_ES), "X")
    )
    caption = (
        "Baseline scenario, 36 tasks x 3 robots. Frontier: the optimal solver at every "
        "integer cap 0-12 (caps above 12 change nothing) and with no cap. Methods: "
        "their balanced-mode allocation, seed 0 for the learners; LTAA also in the other "
        "two modes. Methods on the same point are spread sideways by 1.6 balance units "
        "for legibility. The paper's point uses its reported figures (expected success "
        "76%, loads 22/10/4)."
    )
    image = plots.frontier_figure(
        frontier,
        placed,
        "Exact success/balance frontier with every method",
        caption,
        "frontier.png",
    )
    rows = [[cap, f"{b:.1f}", f"{e:.2f}%"] for cap, b, e in frontier]
    text = (
        f"{caption}\n\n![Frontier]({image})\n\n<details><summary>Frontier points"
        "</summary>\n\n"
        + table(["cap (max_deviation)", "balance", "expected success"], rows)
        + "\n\n</details>\n"
    )
    return text, image


def claude_part() -> str:
    settings = get_settings()
    if resolve_api_key(None, settings) is None:
        return (
            "Claude was not measured: no Anthropic API key was configured "
            "(`ANTHROPIC_API_KEY` / `LTAA_ANTHROPIC_API_KEY`) when this report was "
            "generated.\n"
        )
    base = scenario("baseline").instance
    problem = Problem.build(
        Instance(tasks=base.tasks[:CLAUDE_TASKS], robots=base.robots), Mode.BALANCED
    )
    start = time.perf_counter()
    sol = get_solver("ltaa", settings=settings).solve(problem, options={"reasoner": "anthropic"})
    seconds = time.perf_counter() - start
    n = problem.instance.n_tasks
    es = compute_metrics(problem.instance, sol.assignment).expected_success
    u = sol.usage
    return (
        f"Claude (`{settings.default_model}`, temperature 0.1) through the `ltaa` solver on the "
        f"first {n} baseline tasks, `balanced`, one run: {u.llm_calls} calls, "
        f"{u.input_tokens / n:,.0f} input + {u.output_tokens / n:,.0f} output tokens per task "
        f"(from the API's usage), {fmt_time(seconds / n)} per task, "
        f"{sol.details.get('retries', 0)} retries, {sol.details.get('fallbacks', 0)} "
        f"fallbacks, expected success {_pct(es):.2f}%.\n"
    )


def run() -> Section:
    methods, methods_img = methods_part()
    scen, scen_img = scenarios_part()
    modes, modes_img = modes_part()
    dist, dist_imgs = distribution_part()
    front, front_img = frontier_part()
    body = (
        "### Methods comparison (Fig. 15)\n\n"
        + methods
        + "\n### Scenarios (Fig. 16)\n\n"
        + scen
        + "\n### Modes (Fig. 17)\n\n"
        + modes
        + "\n### Workload distribution and feature success (Figs. 18-19)\n\n"
        + dist
        + "\n### The exact success/balance frontier\n\n"
        + front
        + "\n### RL baselines over seeds\n\nSee the learners section: five seeds, mean, "
        "standard deviation, min/max and the figure `img/rl_seeds.png`.\n"
        + "\n### Claude: tokens and seconds per task\n\n"
        + claude_part()
    )
    return Section(
        "Paper experiments on our data",
        body,
        [methods_img, scen_img, modes_img, *dist_imgs, front_img],
    )
