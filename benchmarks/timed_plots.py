"""The figure of the timed-schedules section: makespan per instance and method, with
CP-SAT's makespan and proven bound (kept apart from `plots.py`, which is near its size
limit)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless

import matplotlib.pyplot as plt
import numpy as np

from benchmarks.common import IMG
from benchmarks.plots import PALETTE, save


def makespan_figure(
    instances: Sequence[str],
    cpsat: Mapping[str, tuple[float, float]],
    methods: Mapping[tuple[str, str], float],
    name: str,
    directory: Path = IMG,
) -> str:
    """One panel per instance: each method's list-schedule makespan relative to CP-SAT's
    bound (1.0 = the bound), CP-SAT's own makespan as the first bar."""
    fig, axes = plt.subplots(1, len(instances), figsize=(3.4 * len(instances), 3.6), sharey=True)
    axes = np.atleast_1d(axes)
    every = ["CP-SAT", *dict.fromkeys(m for _, m in methods)]
    colour = {m: PALETTE[i % len(PALETTE)] for i, m in enumerate(every)}  # one per method
    for ax, label in zip(axes, instances, strict=True):
        makespan, bound = cpsat[label]
        names = ["CP-SAT"] + [m for (lab, m) in methods if lab == label]
        values = [makespan] + [v for (lab, _), v in methods.items() if lab == label]
        ratios = [v / bound for v in values]
        ax.bar(range(len(names)), ratios, color=[colour[m] for m in names])
        ax.axhline(1.0, color="black", linewidth=0.8, linestyle="--")
        ax.set_xticks(range(len(names)), names, rotation=45, ha="right", fontsize=8)
        ax.set_title(label.replace("`", ""), fontsize=9)
    axes[0].set_ylabel("makespan / CP-SAT's proven bound")
    fig.suptitle(
        "Makespan of each method's plan (dashed: CP-SAT's proven lower bound at the optimal "
        "expected success; a plan that gives up success may be shorter)",
        fontsize=10,
    )
    return save(fig, name, directory)


def gap_figure(
    trajectories: Mapping[str, Sequence[Sequence[float]]],
    limits: Sequence[float],
    det_per_s: float,
    name: str,
    directory: Path = IMG,
) -> str:
    """Gap to the proven bound against the time limit, one line per site: each point the
    answer of a run with that limit (read off the trajectory of the longest run)."""
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    for i, (label, points) in enumerate(trajectories.items()):
        xs, ys = [], []
        for limit in limits:
            reached = [p for p in points if p[0] <= limit * det_per_s + 1e-6]
            if reached:
                makespan, bound = reached[-1][3], reached[-1][4]
                xs.append(limit)
                ys.append(100 * max(0.0, (makespan - bound) / makespan) if makespan else 0.0)
        ax.plot(xs, ys, marker="o", color=PALETTE[i % len(PALETTE)], label=label)
    ax.set_xscale("log")
    ax.set_xticks(list(limits), [f"{v:g}" for v in limits])
    ax.set_xlabel("time_limit_s (deterministic budget)")
    ax.set_ylabel("gap to the proven bound (%)")
    ax.legend(fontsize=8)
    ax.set_title("Gap against the time limit (never worse with more time)", fontsize=10)
    return save(fig, name, directory)
