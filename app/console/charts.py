"""The run page's charts as inline SVG, drawn on the server: no script, no external
resource, readable in print (dark strokes on no background, values written as text), and
described for screen readers (role="img" with a title; the values are in the page too)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from html import escape

from markupsafe import Markup

INK = "#1b1b1b"
BAR = "#1f4e8c"
BAND = "#d9e4f2"
GRID = "#6b6b6b"
ACCENT = "#b3261e"
MAX_LINE_POINTS = 600  # a 10,000-task run's balance line, thinned for the page


def _svg(width: int, height: int, title: str, body: list[str], chart_id: str) -> Markup:
    return Markup(
        f'<svg class="chart" id="{chart_id}" viewBox="0 0 {width} {height}" role="img" '
        f'aria-labelledby="{chart_id}-title" xmlns="http://www.w3.org/2000/svg" '
        f'font-family="system-ui, sans-serif" font-size="12">'
        f'<title id="{chart_id}-title">{escape(title)}</title>' + "".join(body) + "</svg>"
    )


def _text(x: float, y: float, text: str, anchor: str = "start", extra: str = "") -> str:
    return (
        f'<text x="{x:.1f}" y="{y:.1f}" text-anchor="{anchor}" fill="{INK}" {extra}>'
        f"{escape(text)}</text>"
    )


def workload_chart(
    robots: Sequence[str], loads: Sequence[int], target: float, lower: int, upper: int | None
) -> Markup:
    """One horizontal bar per robot, the target load as a line, the cap as a band."""
    left, right, row, top = 150, 60, 28, 24
    width = 640
    height = top + row * len(robots) + 34
    plot = width - left - right
    scale_max = max([*loads, upper or 0, target, 1])

    def x(value: float) -> float:
        return left + plot * value / scale_max

    body: list[str] = []
    if upper is not None:
        body.append(
            f'<rect x="{x(lower):.1f}" y="{top - 6}" width="{x(upper) - x(lower):.1f}" '
            f'height="{row * len(robots) + 6}" fill="{BAND}"/>'
        )
    for i, (name, load) in enumerate(zip(robots, loads, strict=True)):
        y = top + i * row
        label = name if len(name) <= 22 else name[:21] + "…"
        body.append(_text(left - 8, y + 15, label, "end"))
        body.append(
            f'<rect x="{left}" y="{y + 3}" width="{x(load) - left:.1f}" height="{row - 8}" '
            f'fill="{BAR}"/>'
        )
        body.append(_text(x(load) + 4, y + 15, str(load)))
    base = top + row * len(robots)
    body.append(
        f'<line x1="{x(target):.1f}" y1="{top - 8}" x2="{x(target):.1f}" y2="{base + 2}" '
        f'stroke="{ACCENT}" stroke-width="2" stroke-dasharray="5 3"/>'
    )
    cap = f"cap band {lower}–{upper} tasks" if upper is not None else "no cap"
    body.append(_text(left, base + 22, f"target load W = {target:g} (dashed); {cap} (shaded)"))
    title = "Workload per robot: " + ", ".join(
        f"{n} {v}" for n, v in zip(robots, loads, strict=True)
    )
    return _svg(width, height, title, body, "chart-workload")


def _thin(values: Sequence[float]) -> list[tuple[int, float]]:
    if len(values) <= MAX_LINE_POINTS:
        return list(enumerate(values))
    step = len(values) / MAX_LINE_POINTS
    picked = sorted({int(i * step) for i in range(MAX_LINE_POINTS)} | {len(values) - 1})
    return [(i, values[i]) for i in picked]


def _axes(left: int, top: int, plot_w: int, plot_h: int) -> list[str]:
    return [
        f'<line x1="{left}" y1="{top + plot_h}" x2="{left + plot_w}" y2="{top + plot_h}" '
        f'stroke="{GRID}"/>',
        f'<line x1="{left}" y1="{top}" x2="{left}" y2="{top + plot_h}" stroke="{GRID}"/>',
    ]


def balance_chart(balance: Sequence[float], n_tasks: int) -> Markup:
    """Balance score (0-100) after each decision, over the task queue."""
    left, top, plot_w, plot_h = 48, 16, 560, 180
    width, height = left + plot_w + 24, top + plot_h + 44
    body = _axes(left, top, plot_w, plot_h)
    for v in (0, 50, 100):
        y = top + plot_h * (1 - v / 100)
        body.append(_text(left - 6, y + 4, str(v), "end"))
        body.append(
            f'<line x1="{left}" y1="{y:.1f}" x2="{left + plot_w}" y2="{y:.1f}" '
            f'stroke="{GRID}" stroke-opacity="0.3"/>'
        )
    span = max(1, n_tasks - 1)
    points = _thin(balance)
    if points:
        path = " ".join(
            f"{left + plot_w * i / span:.1f},{top + plot_h * (1 - v / 100):.1f}" for i, v in points
        )
        body.append(f'<polyline points="{path}" fill="none" stroke="{BAR}" stroke-width="2"/>')
    body.append(_text(left, top + plot_h + 18, "task 1", "start"))
    body.append(_text(left + plot_w, top + plot_h + 18, f"task {n_tasks}", "end"))
    body.append(_text(left + plot_w / 2, top + plot_h + 36, "balance score after each decision"))
    last = f"{balance[-1]:.1f}" if balance else "none yet"
    title = f"Balance over the run: {len(balance)} of {n_tasks} decisions, latest {last}"
    return _svg(width, height, title, body, "chart-balance")


@dataclass(frozen=True)
class PlotPoint:
    label: str
    balance: float  # 0..100
    success_pct: float  # 0..100


def frontier_chart(frontier: Sequence[PlotPoint], run: PlotPoint | None) -> Markup:
    """Expected success against balance: the exact optimum at each cap (line and dots) and
    the run (a red diamond). Everything below the line gives away success for nothing."""
    left, top, plot_w, plot_h = 56, 16, 540, 240
    width, height = left + plot_w + 40, top + plot_h + 48
    values = [p.success_pct for p in frontier] + ([run.success_pct] if run else [])
    lo, hi = min(values), max(values)
    pad = max(0.5, (hi - lo) * 0.1)
    lo, hi = lo - pad, hi + pad

    def xy(p: PlotPoint) -> tuple[float, float]:
        return (
            left + plot_w * p.balance / 100,
            top + plot_h * (1 - (p.success_pct - lo) / (hi - lo)),
        )

    body = _axes(left, top, plot_w, plot_h)
    for b in (0, 25, 50, 75, 100):
        body.append(_text(left + plot_w * b / 100, top + plot_h + 16, str(b), "middle"))
    for v in (lo + pad, hi - pad):
        y = top + plot_h * (1 - (v - lo) / (hi - lo))
        body.append(_text(left - 6, y + 4, f"{v:.1f}%", "end"))
    ordered = sorted(frontier, key=lambda p: p.balance)
    path = " ".join(f"{x:.1f},{y:.1f}" for x, y in map(xy, ordered))
    body.append(f'<polyline points="{path}" fill="none" stroke="{BAR}" stroke-width="2"/>')
    for p in ordered:
        x, y = xy(p)
        body.append(
            f'<circle cx="{x:.1f}" cy="{y:.1f}" r="4" fill="{BAR}">'
            f"<title>{escape(p.label)}: balance {p.balance:.1f}, success "
            f"{p.success_pct:.2f}%</title></circle>"
        )
    if run is not None:
        x, y = xy(run)
        body.append(
            f'<path d="M{x:.1f},{y - 8:.1f} L{x + 8:.1f},{y:.1f} L{x:.1f},{y + 8:.1f} '
            f'L{x - 8:.1f},{y:.1f} Z" fill="{ACCENT}" stroke="{INK}"/>'
        )
        body.append(_text(x + 10, y - 8, "this run", "start", 'font-weight="bold"'))
    body.append(
        _text(left + plot_w / 2, top + plot_h + 36, "balance score (exact optimum: line)", "middle")
    )
    where = (
        f"this run at balance {run.balance:.1f}, success {run.success_pct:.2f}%"
        if run
        else "this run is not finished"
    )
    title = f"Expected success against balance: exact optimum at {len(frontier)} caps; {where}"
    return _svg(width, height, title, body, "chart-frontier")
