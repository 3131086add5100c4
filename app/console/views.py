"""What the run page shows, assembled from app.runs (the services the JSON API uses)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from markupsafe import Markup
from sqlalchemy.orm import Session, sessionmaker

from app.console import browse, charts
from app.console.frontier import FrontierPoint, cached_frontier, frontier
from app.domain.errors import RunNotFoundError, StateConflictError
from app.domain.models import TaskId
from app.graph.validation import CRITERION_TITLES, WEIGHTS
from app.plans import current, revisions
from app.plans import diff as diffs
from app.runs import views as run_views
from app.schedule_views import gantt_svg
from app.store.models import Attempt

DECISIONS_PER_PAGE = 25
# Up to here the frontier and a revision's diff take milliseconds: drawn in the page.
# Beyond, the page comes without them and its script fetches each after the page loads.
INLINE_TASKS = 1000
DIFF_ROWS = 200  # rows of each diff list shown; GET /runs/{id}/diff has them all


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
class TeamLine:
    """One unit of a team decision (docs/allocation.md#teams): its feature, the member
    covering it, and that member's sentence from the reasoner's **Team** block."""

    feature: str
    robot: str
    reason: str | None


def team_lines(team: list[dict[str, str]] | None, attempt: Attempt | None) -> list[TeamLine]:
    """The decision's members in unit order, each with the reason its final attempt gave
    (the parsed **Team** line of the same unit naming the same robot; None when it gave
    none, as a fallback or an optimizer's team does). Empty for a one-robot decision."""
    parsed = (attempt.parsed or {}).get("team") if attempt is not None else None
    said = parsed if isinstance(parsed, list) else []
    out = []
    for i, member in enumerate(team or []):
        line = said[i] if i < len(said) and isinstance(said[i], dict) else {}
        same = line.get("feature") == member["feature"] and line.get("robot") == member["robot"]
        reason = str(line.get("reason") or "") if same else ""
        out.append(TeamLine(member["feature"], member["robot"], reason or None))
    return out


@dataclass(frozen=True)
class FrontierView:
    svg: Markup
    points: list[charts.PlotPoint]
    run_point: charts.PlotPoint | None


def frontier_view(view: browse.RunOverview, points: list[FrontierPoint]) -> FrontierView:
    plotted = [
        charts.PlotPoint(
            "no cap" if p.max_deviation is None else f"cap ±{p.max_deviation:g}",
            p.balance_score,
            100 * p.expected_success,
        )
        for p in points
    ]
    run_point = (
        charts.PlotPoint("this run", view.balance_score, 100 * view.expected_success)
        if view.balance_score is not None and view.expected_success is not None
        else None
    )
    return FrontierView(charts.frontier_chart(plotted, run_point), plotted, run_point)


def run_frontier(*, sessions: sessionmaker[Session], run_id: str, cache_dir: Path) -> FrontierView:
    """The frontier part of the run page, computing (and caching) the frontier if need be."""
    view = browse.overview(sessions=sessions, run_id=run_id)
    return frontier_view(view, frontier(spec=view.spec, run_id=run_id, cache_dir=cache_dir))


@dataclass(frozen=True)
class DiffView:
    """A revision against its parent, its long lists cut to DIFF_ROWS for the page; or,
    with the parent's rows gone (archived), only the parent's id (`diff` None)."""

    parent: str
    parent_revision: int
    diff: diffs.Diff | None
    robot_changes: list[dict[str, Any]]
    added_tasks: list[TaskId]
    removed_tasks: list[TaskId]
    rows_shown: int


def diff_view(*, sessions: sessionmaker[Session], run_id: str) -> DiffView:
    run = browse.run_row(sessions=sessions, run_id=run_id)
    if run.revision_of is None:
        raise revisions.RevisionConflictError(
            f"run '{run_id}' is not a revision: it has no diff against a parent"
        )
    try:
        d = diffs.diff(sessions=sessions, run_id=run_id)
    except RunNotFoundError:
        return DiffView(run.revision_of, run.revision - 1, None, [], [], [], DIFF_ROWS)
    return DiffView(
        parent=d.parent,
        parent_revision=run.revision - 1,  # a revision is its parent's revision + 1
        diff=d,
        robot_changes=d.robot_changes[:DIFF_ROWS],
        added_tasks=d.added_tasks[:DIFF_ROWS],
        removed_tasks=d.removed_tasks[:DIFF_ROWS],
        rows_shown=DIFF_ROWS,
    )


@dataclass(frozen=True)
class RunPage:
    overview: browse.RunOverview
    page: run_views.DecisionPage
    page_number: int
    pages: int
    open_decision: int | None
    workload_svg: Markup
    balance_svg: Markup
    frontier: FrontierView | None  # None: not computed yet (the page loads it separately)
    cap_lower: int
    cap_upper: int | None
    model: str | None
    stream_cursor: str
    lineage: list[revisions.LineageEntry]  # root to head; one entry: never revised
    diff: DiffView | None  # a revision's, when drawn in the page (see diff_deferred)
    diff_deferred: bool  # a large revision: the page's script fetches its diff
    # docs/schedules.md#reading-a-runs-schedule, a timed run: its schedule as a Gantt chart once
    # every task is decided (None: untimed, or not decided yet, which `timed` tells apart), with its
    # makespan.
    gantt_svg: Markup | None = None
    makespan: float | None = None
    timed: bool = False

    @property
    def head(self) -> revisions.LineageEntry:
        return self.lineage[-1]


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
    with sessions() as session:
        page = run_views.decision_page(
            session,
            run_id,
            offset=(page_number - 1) * DECISIONS_PER_PAGE,
            limit=DECISIONS_PER_PAGE,
            prompts=False,
            from_task=True,
        )
    cap = spec.problem.cap
    upper = None if cap.max_deviation is None else cap.upper
    # A first visit to a large run would wait for the exact optimum at every cap: the page
    # then comes without it, and its script fetches it (which computes and caches it).
    cached = cached_frontier(run_id=run_id, cache_dir=cache_dir)
    if cached is None and run.n_tasks <= INLINE_TASKS:
        cached = frontier(spec=spec, run_id=run_id, cache_dir=cache_dir)
    last_seq = view.events[-1].seq if view.events else 0
    lineage = revisions.lineage_entries(sessions=sessions, run_id=run_id)
    is_revision = run.revision_of is not None
    # The diff reads both runs' decisions: the parent may be the large one.
    parent = next((e.run for e in lineage if e.run.id == run.revision_of), None)
    largest = max(run.n_tasks, parent.n_tasks if parent is not None else 0)
    inline_diff = is_revision and largest <= INLINE_TASKS
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
        frontier=frontier_view(view, cached) if cached is not None else None,
        cap_lower=cap.lower,
        cap_upper=upper,
        model=spec.model,
        stream_cursor=f"{last_seq}-{view.allocated}",
        lineage=lineage,
        diff=diff_view(sessions=sessions, run_id=run_id) if inline_diff else None,
        diff_deferred=is_revision and not inline_diff,
        **gantt(sessions=sessions, run_id=run_id, timed=spec.problem.instance.timed),
    )


def gantt(*, sessions: sessionmaker[Session], run_id: str, timed: bool) -> dict[str, Any]:
    """A timed run's Gantt chart (server-rendered by app.schedule_views, the critical path
    marked), once its schedule is whole; nothing for an untimed run. Its current
    schedule: the decisions re-timed by the site's execution reports (app.plans.current)."""
    if not timed:
        return {}
    try:
        planned = current.current_schedule(sessions=sessions, run_id=run_id)
    except StateConflictError:  # not every task decided yet
        planned = None
    if planned is None:
        return {"timed": True}
    problem, schedule = planned
    # gantt_svg escapes every name it writes (task ids, robot labels).
    svg = Markup(gantt_svg(problem, schedule))
    return {"timed": True, "gantt_svg": svg, "makespan": schedule.makespan}
