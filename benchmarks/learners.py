"""The reinforcement learners over five seeds: quality, spread, gap to optimal, training time.

Issue 2's acceptance: on baseline/balanced each learner is within 3 points of `optimal`.
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from benchmarks import plots
from benchmarks.cache import solved
from benchmarks.common import Section, fmt_time, table
from benchmarks.solvers import LEARNER_SEEDS, LEARNERS

TOLERANCE_POINTS = 3.0
LABELS = {"q_learning": "Q-learning (tabular)", "dqn": "DQN (SB3)"}


@dataclass(frozen=True)
class SeedSummary:
    solver: str
    es: list[float]  # %, one per seed
    seconds: list[float]
    optimum: float  # %

    @property
    def gaps(self) -> list[float]:
        return [self.optimum - e for e in self.es]

    @property
    def within(self) -> int:
        # 1e-9: a seed that reaches the optimum must not fail on float noise.
        return sum(g <= TOLERANCE_POINTS + 1e-9 for g in self.gaps)


def summarise(
    solver: str, es: Sequence[float], seconds: Sequence[float], optimum: float
) -> SeedSummary:
    return SeedSummary(solver, list(es), list(seconds), optimum)


def summary_row(s: SeedSummary) -> list[str]:
    std = statistics.stdev(s.es) if len(s.es) > 1 else 0.0
    mean_gap = statistics.fmean(s.gaps)
    verdict = "met" if s.within == len(s.es) else "**missed**"
    return [
        f"`{s.solver}`",
        f"{statistics.fmean(s.es):.2f}% ± {std:.2f}",
        f"{min(s.es):.2f}% / {max(s.es):.2f}%",
        f"{mean_gap:.2f} (worst {max(s.gaps):.2f})",
        f"{s.within}/{len(s.es)} — {verdict}",
        f"{fmt_time(statistics.median(s.seconds))} "
        f"({fmt_time(min(s.seconds))}-{fmt_time(max(s.seconds))})",
    ]


def collect() -> list[SeedSummary]:
    optimum = solved("optimal").metrics.expected_success * 100
    out = []
    for name in LEARNERS:
        runs = [solved(name, seed=s) for s in LEARNER_SEEDS]
        out.append(
            summarise(
                name,
                [r.metrics.expected_success * 100 for r in runs],
                [r.seconds for r in runs],
                optimum,
            )
        )
    return out


def run() -> Section:
    summaries = collect()
    optimum = summaries[0].optimum
    per_seed = table(
        ["seed", *(f"`{s.solver}` expected success (gap, time)" for s in summaries)],
        [
            [
                seed,
                *(
                    f"{s.es[i]:.2f}% ({s.gaps[i]:.2f} pts, {fmt_time(s.seconds[i])})"
                    for s in summaries
                ),
            ]
            for i, seed in enumerate(LEARNER_SEEDS)
        ],
    )
    seeds_text = f"seeds {LEARNER_SEEDS[0]}-{LEARNER_SEEDS[-1]}"
    image = plots.seeds_figure(
        {LABELS[s.solver]: s.es for s in summaries},
        optimum,
        TOLERANCE_POINTS,
        f"RL baselines over {len(LEARNER_SEEDS)} seeds (baseline, balanced)",
        f"Baseline scenario, 36 tasks x 3 robots, balanced mode (cap 4), default options, "
        f"{seeds_text}, one training per seed. Error bars: mean ± sample std.",
        "rl_seeds.png",
    )
    body = (
        f"Baseline scenario (36 × 3), `balanced` mode (cap 4), default options, {seeds_text}; "
        "each seed is one training from scratch (wall time of the `solve()` call, training "
        f"included). `optimal` reaches {optimum:.2f}%. Gap = optimal − learner, in "
        f"percentage points; acceptance: every seed within {TOLERANCE_POINTS:g} points.\n\n"
        + table(
            [
                "solver",
                "expected success, mean ± std",
                "min / max",
                "gap to optimal, points: mean",
                "seeds within 3 points",
                "training time: median (min-max)",
            ],
            [summary_row(s) for s in summaries],
        )
        + f"\n\nPer seed:\n\n{per_seed}\n\n![RL baselines over seeds]({image})\n"
    )
    return Section("Learners over five seeds", body)
