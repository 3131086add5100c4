"""What the run page shows, assembled from app.runs (the services the JSON API uses)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from markupsafe import Markup
from sqlalchemy.orm import Session, sessionmaker

from app.console import charts
from app.graph.validation import CRITERION_TITLES, WEIGHTS
from app.runs import browse
from app.runs.frontier import frontier
from app.store.models import Attempt

DECISIONS_PER_PAGE = 25


@dataclass(frozen=True)
class Score:
    key: str
    title: str
    weight: float
    value: float | None


def scores_of(attempt: Attempt | None) -> list[Score]:
    """The eight criteria in the paper's order, with the attempt's score for each."""
    given: dict[str, Any] = (attempt.scores or {}) if attempt is not None else {}
    return [
        Score(key, CRITERION_TITLES[key], weight, _float(given.get(key)))
        for key, weight in WEIGHTS.items()
    ]


def _float(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) else None


def final_attempt(attempts: list[Attempt]) -> Attempt | None:
    accepted = [a for a in attempts if a.accepted]
    if accepted:
        return accepted[-1]
    return attempts[-1] if attempts else None


@dataclass(frozen=True)
class RunPage:
    overview: browse.RunOverview
    page: browse.DecisionPage
    page_number: int
    pages: int
    open_decision: int | None
    workload_svg: Markup
    balance_svg: Markup
    frontier_svg: Markup
    frontier_points: list[charts.PlotPoint]
    run_point: charts.PlotPoint | None
    cap_lower: int
    cap_upper: int | None
    model: str | None
    stream_cursor: str


def run_page(
    *,
    sessions: sessionmaker[Session],
    run_id: str,
    page_number: int,
    open_decision: int | None,
    cache_dir: Path,
) -> RunPage:
    view = browse.overview(sessions=sessions, run_id=run_id)
    run, spec = view.run, view.spec
    pages = max(1, -(-run.n_tasks // DECISIONS_PER_PAGE))
    if open_decision is not None and 0 <= open_decision < run.n_tasks:
        page_number = open_decision // DECISIONS_PER_PAGE + 1
    page_number = min(max(1, page_number), pages)
    page = browse.decision_page(
        sessions=sessions,
        run_id=run_id,
        offset=(page_number - 1) * DECISIONS_PER_PAGE,
        limit=DECISIONS_PER_PAGE,
    )
    cap = spec.problem.cap
    upper = None if cap.max_deviation is None else cap.upper
    points = [
        charts.PlotPoint(
            "no cap" if p.max_deviation is None else f"cap ±{p.max_deviation:g}",
            p.balance_score,
            100 * p.expected_success,
        )
        for p in frontier(spec=spec, run_id=run_id, cache_dir=cache_dir)
    ]
    run_point = (
        charts.PlotPoint("this run", view.balance_score, 100 * view.expected_success)
        if view.balance_score is not None and view.expected_success is not None
        else None
    )
    last_seq = view.events[-1].seq if view.events else 0
    return RunPage(
        overview=view,
        page=page,
        page_number=page_number,
        pages=pages,
        open_decision=open_decision,
        workload_svg=charts.workload_chart(
            view.robots, view.loads, spec.problem.instance.target_load, cap.lower, upper
        ),
        balance_svg=charts.balance_chart(view.balance, run.n_tasks),
        frontier_svg=charts.frontier_chart(points, run_point),
        frontier_points=points,
        run_point=run_point,
        cap_lower=cap.lower,
        cap_upper=upper,
        model=spec.model,
        stream_cursor=f"{last_seq}-{view.allocated}",
    )
