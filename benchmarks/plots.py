"""Matplotlib figures for the report. Each function takes plain numbers and a file name, so
the smoke test can draw them from toy data without running the bench.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: the bench runs in CI and over SSH

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.artist import Artist
from matplotlib.figure import Figure

from benchmarks.common import IMG

PALETTE = ["#4C72B0", "#DD8452", "#55A868", "#C44E52", "#8172B3", "#937860", "#DA8BC3", "#8C8C8C"]
TAB10 = [plt.get_cmap("tab10")(i) for i in range(10)]


def save(fig: Figure, name: str, directory: Path = IMG) -> str:
    """Write the PNG and return its path relative to docs/ for the markdown."""
    directory.mkdir(parents=True, exist_ok=True)
    fig.savefig(directory / name, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return f"img/{name}"


def _footer(
    fig: Figure,
    caption: str,
    legend: tuple[list[Artist], list[str]] | None = None,
    ncol: int = 3,
) -> None:
    """Legend and caption under the axes, so neither hides data.

    `legend` is what get_legend_handles_labels returns: handles and labels go together."""
    rows = 0
    handles, labels = legend or ([], [])
    if handles:
        fig.legend(
            handles,
            labels,
            loc="upper center",
            bbox_to_anchor=(0.5, 0.0),
            ncol=ncol,
            fontsize=8,
            frameon=False,
        )
        rows = math.ceil(len(handles) / ncol)
    height = fig.get_size_inches()[1]
    fig.text(
        0.01, -(0.2 * rows + 0.15) / height, caption, fontsize=7.5, ha="left", va="top", wrap=True
    )


@dataclass(frozen=True)
class MethodPoint:
    label: str
    es: float  # expected success, %
    es_range: tuple[float, float] | None  # spread over seeds, % (None: deterministic)
    completion: float  # simulated completion, %
    completion_ci: tuple[float, float]


def methods_figure(
    points: Sequence[MethodPoint], title: str, caption: str, name: str, directory: Path = IMG
) -> str:
    fig, ax = plt.subplots(figsize=(8.5, 0.55 * len(points) + 1.8))
    y = np.arange(len(points))[::-1]
    for yi, p in zip(y, points, strict=True):
        lo, hi = p.completion_ci
        ax.errorbar(
            p.completion,
            yi - 0.15,
            xerr=[[p.completion - lo], [hi - p.completion]],
            fmt="o",
            color=PALETTE[0],
            capsize=4,
            label="simulated completion, 95% interval" if yi == y[0] else None,
        )
        err = None if p.es_range is None else [[p.es - p.es_range[0]], [p.es_range[1] - p.es]]
        ax.errorbar(
            p.es,
            yi + 0.15,
            xerr=err,
            fmt="D",
            color=PALETTE[1],
            capsize=4,
            label="expected success (whiskers: min-max over seeds)" if yi == y[0] else None,
        )
        ax.annotate(
            f"{p.es:.1f}%",
            (p.es, yi + 0.15),
            xytext=(8, 4),
            textcoords="offset points",
            fontsize=8,
            color=PALETTE[1],
        )
    ax.set_yticks(y, [p.label for p in points])
    ax.set_xlabel("success (% of tasks)")
    ax.set_title(title)
    ax.grid(axis="x", alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    _footer(fig, caption, (handles, labels), ncol=2)
    return save(fig, name, directory)


@dataclass(frozen=True)
class Panel:
    categories: Sequence[str]
    series: Mapping[str, Sequence[float]]  # legend label -> one value per category
    ylabel: str
    ylim: tuple[float, float] | None = None
    hlines: dict[str, float] = field(default_factory=dict)  # label -> y
    band: tuple[float, float] | None = None  # shaded allowed range (the workload cap)


def _bars(ax: plt.Axes, panel: Panel) -> None:
    x = np.arange(len(panel.categories))
    width = 0.8 / max(1, len(panel.series))
    for i, (label, values) in enumerate(panel.series.items()):
        ax.bar(
            x + (i - (len(panel.series) - 1) / 2) * width,
            values,
            width,
            label=label,
            color=PALETTE[i % len(PALETTE)],
            zorder=2,
        )
    if panel.band is not None:
        ax.axhspan(
            *panel.band,
            color="grey",
            alpha=0.15,
            zorder=0,
            label=f"allowed by the cap [{panel.band[0]:g}, {panel.band[1]:g}]",
        )
    for j, (label, value) in enumerate(panel.hlines.items()):
        ax.axhline(
            value,
            color="black",
            linestyle=["--", ":", "-."][j % 3],
            linewidth=1,
            label=label,
            zorder=3,
        )
    ax.set_xticks(x, panel.categories)
    ax.set_ylabel(panel.ylabel)
    if panel.ylim is not None:
        ax.set_ylim(*panel.ylim)
    ax.grid(axis="y", alpha=0.3, zorder=1)


def panels_figure(
    panels: Sequence[Panel],
    title: str,
    caption: str,
    name: str,
    directory: Path = IMG,
    width: float = 12.0,
) -> str:
    fig, axes = plt.subplots(1, len(panels), figsize=(width, 4.2), squeeze=False)
    for ax, panel in zip(axes[0], panels, strict=True):
        _bars(ax, panel)
    fig.suptitle(title)
    fig.tight_layout()
    # Every panel plots the same series: one legend for the figure.
    handles, labels = axes[0][0].get_legend_handles_labels()
    _footer(fig, caption, (handles, labels), ncol=min(len(handles), 6))
    return save(fig, name, directory)


@dataclass(frozen=True)
class PlacedPoint:
    label: str
    balance: float
    es: float  # %
    marker: str = "o"


def frontier_figure(
    frontier: Sequence[tuple[str, float, float]],
    points: Sequence[PlacedPoint],
    title: str,
    caption: str,
    name: str,
    directory: Path = IMG,
) -> str:
    """frontier: (cap label, balance score, expected success %) from the exact solver."""
    fig, ax = plt.subplots(figsize=(9, 5.5))
    bal = [b for _, b, _ in frontier]
    es = [e for _, _, e in frontier]
    ax.plot(
        bal,
        es,
        "-",
        color="black",
        linewidth=1.2,
        zorder=1,
        label="exact frontier (optimal at each cap)",
    )
    ax.scatter(bal, es, s=14, color="black", zorder=2)
    seen: set[tuple[float, float]] = set()
    for cap, b, e in frontier:
        if (round(b, 6), round(e, 6)) in seen:  # "no cap" coincides with the largest cap
            continue
        seen.add((round(b, 6), round(e, 6)))
        ax.annotate(
            cap, (b, e), xytext=(3, 3), textcoords="offset points", fontsize=6.5, color="dimgray"
        )
    # Methods that land on the same point are spread sideways (the legend has exact values).
    groups: dict[tuple[float, float], list[int]] = {}
    for i, p in enumerate(points):
        groups.setdefault((round(p.balance, 3), round(p.es, 3)), []).append(i)
    dodge = {i: (j - (len(g) - 1) / 2) * 1.6 for g in groups.values() for j, i in enumerate(g)}
    for i, p in enumerate(points):
        ax.scatter(
            p.balance + dodge[i],
            p.es,
            s=70,
            marker=p.marker,
            color=TAB10[i % len(TAB10)],
            edgecolors="black",
            linewidths=0.5,
            zorder=3,
            label=f"{p.label} ({p.balance:.0f}, {p.es:.1f}%)",
        )
    ax.set_xlabel("balance score B (0-100, higher = more even workload)")
    ax.set_ylabel("expected success (%)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(
        fontsize=7.5,
        loc="upper left",
        bbox_to_anchor=(1.02, 1.0),
        title="method (balance, expected success)",
        title_fontsize=8,
    )
    _footer(fig, caption)
    return save(fig, name, directory)


def seeds_figure(
    per_seed: dict[str, Sequence[float]],
    optimum: float,
    tolerance: float,
    title: str,
    caption: str,
    name: str,
    directory: Path = IMG,
) -> str:
    """Per-seed expected success (%) of each learner, mean +/- std, and the optimum."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, (label, values) in enumerate(per_seed.items()):
        v = np.asarray(values, dtype=float)
        ax.scatter(
            np.full(v.size, i) + np.linspace(-0.12, 0.12, v.size),
            v,
            s=22,
            color=PALETTE[i],
            alpha=0.7,
            label=f"{label}: each seed",
        )
        ax.errorbar(
            i + 0.3,
            v.mean(),
            yerr=v.std(ddof=1) if v.size > 1 else 0,
            fmt="s",
            color=PALETTE[i],
            capsize=5,
            label=f"{label}: mean ± std",
        )
    ax.axhline(optimum, color="black", linestyle="--", linewidth=1, label="optimal")
    ax.axhspan(
        optimum - tolerance,
        optimum,
        color="green",
        alpha=0.08,
        label=f"within {tolerance:g} points of optimal",
    )
    ax.set_xticks(range(len(per_seed)), list(per_seed))
    ax.set_xlim(-0.6, len(per_seed) - 0.2)
    ax.set_ylabel("expected success (%)")
    ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    _footer(fig, caption, (handles, labels), ncol=2)
    return save(fig, name, directory)


def hbar_figure(
    bars: Sequence[tuple[str, float]],
    xlabel: str,
    title: str,
    caption: str,
    name: str,
    directory: Path = IMG,
    log: bool = False,
) -> str:
    fig, ax = plt.subplots(figsize=(8.5, 0.5 * len(bars) + 1.6))
    y = np.arange(len(bars))[::-1]
    ax.barh(y, [v for _, v in bars], color=[PALETTE[i % len(PALETTE)] for i in range(len(bars))])
    for yi, (_, v) in zip(y, bars, strict=True):
        ax.annotate(f"{v:,.0f}", (v, yi), xytext=(4, -3), textcoords="offset points", fontsize=8)
    ax.set_yticks(y, [label for label, _ in bars])
    if log:
        ax.set_xscale("log")
    ax.set_xlabel(xlabel)
    ax.set_title(title)
    ax.grid(axis="x", alpha=0.3)
    _footer(fig, caption)
    return save(fig, name, directory)


def latency_histogram_figure(
    latencies: dict[str, Sequence[float]],
    title: str,
    caption: str,
    name: str,
    directory: Path = IMG,
) -> str:
    """Stacked histogram of request latencies (seconds) by label, p50/p95/p99 of all marked."""
    everything = [v for values in latencies.values() for v in values]
    fig, ax = plt.subplots(figsize=(8.5, 3.6))
    bins = np.linspace(0, max(everything, default=1.0), 41).tolist()
    labels = list(latencies)
    ax.hist(
        [latencies[k] for k in labels],
        bins=bins,
        stacked=True,
        label=labels,
        color=PALETTE[: len(labels)],
    )
    for q, style in ((50, "-"), (95, "--"), (99, ":")):
        x = float(np.percentile(everything, q)) if everything else 0.0
        ax.axvline(x, color="black", linestyle=style, linewidth=1)
        ax.annotate(
            f"p{q}",
            (x, 1),
            xycoords=("data", "axes fraction"),
            xytext=(3, -12),
            textcoords="offset points",
            fontsize=8,
        )
    ax.set_xlabel("latency (s)")
    ax.set_ylabel("calls")
    ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)
    handles, names = ax.get_legend_handles_labels()
    _footer(fig, caption, (handles, names), ncol=len(labels))
    return save(fig, name, directory)
