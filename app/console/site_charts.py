"""The site page's charts as inline SVG (like app.console.charts): each robot's learned
rates with their 90% intervals against the configured ones, and the plans' reliability."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from markupsafe import Markup

from app.console.charts import ACCENT, BAND, BAR, GRID, INK, _svg, _text


@dataclass(frozen=True)
class RateRow:
    label: str  # "heavy · dexterous"
    configured: float
    mean: float
    low: float
    high: float
    reports: int
    marked: bool


def rates_chart(rows: Sequence[RateRow]) -> Markup:
    """One line per (robot, feature): the interval as a band, the learned rate as a dot, the
    configured rate as a tick; the rates farthest from the configured ones in red."""
    left, right, row, top = 190, 90, 24, 30
    width = 680
    height = top + row * max(1, len(rows)) + 30
    plot = width - left - right

    def x(p: float) -> float:
        return left + plot * p

    body: list[str] = []
    for tick in (0.0, 0.25, 0.5, 0.75, 1.0):
        body.append(
            f'<line x1="{x(tick):.1f}" y1="{top - 6}" x2="{x(tick):.1f}" '
            f'y2="{top + row * len(rows)}" stroke="{GRID}" stroke-width="0.5"/>'
        )
        body.append(_text(x(tick), top - 10, f"{tick:.0%}", "middle"))
    for i, r in enumerate(rows):
        y = top + i * row + row / 2
        colour = ACCENT if r.marked else BAR
        body.append(_text(left - 8, y + 4, r.label[:30], "end"))
        span = max(1.0, x(r.high) - x(r.low))
        body.append(
            f'<rect x="{x(r.low):.1f}" y="{y - 5:.1f}" width="{span:.1f}" '
            f'height="10" fill="{BAND}" stroke="{colour}" stroke-width="1"/>'
        )
        body.append(
            f'<line x1="{x(r.configured):.1f}" y1="{y - 9:.1f}" x2="{x(r.configured):.1f}" '
            f'y2="{y + 9:.1f}" stroke="{INK}" stroke-width="2"/>'
        )
        body.append(f'<circle cx="{x(r.mean):.1f}" cy="{y:.1f}" r="4.5" fill="{colour}"/>')
        body.append(_text(width - right + 8, y + 4, f"{r.mean:.0%} n={r.reports}"))
    base = top + row * len(rows)
    body.append(
        _text(left, base + 20, "dot: learned rate; band: 90% interval; bar: configured rate")
    )
    title = "Learned success rates with 90% intervals against the configured rates: " + "; ".join(
        f"{r.label} {r.mean:.0%} (configured {r.configured:.0%}, {r.reports} reports)" for r in rows
    )
    return _svg(width, height, title, body, "chart-rates")


@dataclass(frozen=True)
class Bin:
    predicted: float
    observed: float
    reports: int


def reliability_chart(bins: Sequence[Bin]) -> Markup:
    """Predicted success (what the plans expected) against the share reported done, by
    tenth; on the diagonal the plans were calibrated. Each point is labelled with its count."""
    size, pad = 300, 46
    width, height = size + 2 * pad, size + 2 * pad

    def px(p: float) -> float:
        return pad + size * p

    def py(p: float) -> float:
        return pad + size * (1 - p)

    body = [
        f'<rect x="{pad}" y="{pad}" width="{size}" height="{size}" fill="none" stroke="{GRID}"/>',
        f'<line x1="{px(0):.1f}" y1="{py(0):.1f}" x2="{px(1):.1f}" y2="{py(1):.1f}" '
        f'stroke="{GRID}" stroke-dasharray="4 3"/>',
        _text(pad + size / 2, height - 8, "predicted success", "middle"),
        _text(
            12, pad + size / 2, "observed", "middle", f'transform="rotate(-90 12 {pad + size / 2})"'
        ),
    ]
    for tick in (0.0, 0.5, 1.0):
        body.append(_text(px(tick), pad + size + 16, f"{tick:.0%}", "middle"))
        body.append(_text(pad - 6, py(tick) + 4, f"{tick:.0%}", "end"))
    points = " ".join(f"{px(b.predicted):.1f},{py(b.observed):.1f}" for b in bins)
    if len(bins) > 1:
        body.append(f'<polyline points="{points}" fill="none" stroke="{BAR}" stroke-width="2"/>')
    for b in bins:
        body.append(
            f'<circle cx="{px(b.predicted):.1f}" cy="{py(b.observed):.1f}" r="4" fill="{BAR}"/>'
        )
        body.append(_text(px(b.predicted) + 6, py(b.observed) - 6, str(b.reports)))
    title = "Reliability: " + (
        "; ".join(
            f"predicted {b.predicted:.0%}, observed {b.observed:.0%} ({b.reports} reports)"
            for b in bins
        )
        or "no reports yet"
    )
    return _svg(width, height, title, body, "chart-reliability")
