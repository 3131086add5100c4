"""A schedule as a Gantt chart: server-rendered SVG, one lane per robot.

Each task is a bar with a <title> (the hover text: task, robot, times, zone, travel);
bars on the critical path carry the class `critical`; travel and idle are drawn as one
path each per lane, so a 1,000-task chart stays light (one element per task, not three).
The page that embeds the chart may restyle it through the classes; the chart carries its
own defaults and a legend.

A team task (docs/allocation.md#teams) has a bar in every member's lane, each with the
class `team`, the same `data-task` and the same title naming the whole team; a thin
connector (`team-link`) joins them across the lanes at the task's start, so the eye reads
one task held by several robots.

Each typed link (docs/schedules.md#links) is an arrow from the predecessor's bar to the
successor's, drawn in one path per type (`link`, with `link-fs`, `link-ss`, `link-ff` or
`link-sf`; its heads in a `link-head` path beside it), at the ends the link ties: out of
the predecessor's right end (FS, FF) or left end (SS, SF), into the successor's start (FS,
SS) or end (FF, SF), lane to lane (a team task's: its first member's), along the successor
lane's margin. Drawn after the lanes (their backgrounds are opaque); an arrow stops at the
edge of the bar it enters.
"""

from __future__ import annotations

from xml.sax.saxutils import escape, quoteattr

from app.domain.problem import Problem
from app.domain.scheduling.schedule import Schedule
from app.schedule_views.json_view import LaneItem, LaneKind, critical_tasks, lanes

WIDTH = 1200
GUTTER = 150  # robot names
TOP = 28  # the time axis
LANE = 26
BAR = 18
LEGEND = 34
LABEL_MIN_PX = 36  # a bar this wide gets its task id written on it
_TICK_STEPS = (5, 10, 15, 30, 60, 120, 240, 480, 720, 1440, 2880, 10080, 20160, 43200)

STYLE = (
    ".lane{fill:#f4f5f7}.shift{fill:#e3e7ee}.task{fill:#4c78a8;stroke:#fff;stroke-width:.5}"
    ".task.critical{fill:#d62728}.travel{fill:#f2b447}.idle{fill:url(#idle-hatch)}"
    ".axis{stroke:#aab;stroke-width:.5}.end{stroke:#d62728;stroke-dasharray:4 3}"
    "text{font:11px sans-serif;fill:#222}.bar-label{fill:#fff;font-size:9px}"
    ".task.team{stroke:#1b1f24;stroke-width:1}.team-link{stroke:#1b1f24;stroke-width:1.5}"
    ".link{fill:none;stroke:#55606e;stroke-width:1}.link-ss,.link-ff,.link-sf"
    "{stroke-dasharray:3 2}.link-head{fill:#55606e}"
)
# Which end of each bar a link ties (docs/schedules.md#links): the predecessor's, then the
# successor's; True is the bar's end (right), False its start (left).
LINK_ENDS = {"FS": (True, False), "SS": (False, False), "FF": (True, True), "SF": (False, True)}
STUB = 5  # px a link leaves its bar before it turns, and enters the other bar after


def _n(x: float) -> str:
    """A coordinate to one decimal: enough on screen, and half the bytes of full floats."""
    text = f"{x:.1f}"
    return text[:-2] if text.endswith(".0") else text


def _tick_step(makespan: float) -> int:
    for step in _TICK_STEPS:
        if makespan / step <= 12:
            return step
    return _TICK_STEPS[-1] * max(1, round(makespan / _TICK_STEPS[-1] / 12))


def _minutes_label(minute: float) -> str:
    hours, mins = divmod(round(minute), 60)
    return f"{hours} h" if mins == 0 else f"{hours} h {mins:02d}"


def _path(items: list[LaneItem], x: float, scale: float, y: float) -> str:
    """One path of rectangles: M x,y h w v h h -w z per item."""
    return "".join(
        f"M{_n(x + it.start * scale)} {_n(y)}h{_n((it.end - it.start) * scale)}"
        f"v{BAR}h{_n(-(it.end - it.start) * scale)}z"
        for it in items
    )


def gantt_svg(problem: Problem, schedule: Schedule) -> str:
    instance, tm = problem.instance, problem.instance.timing
    span = max(schedule.makespan, 1.0)
    scale = (WIDTH - GUTTER - 10) / span
    height = TOP + LANE * instance.n_robots + LEGEND
    critical = critical_tasks(schedule)
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height}" '
        f'viewBox="0 0 {WIDTH} {height}" role="img" '
        f'aria-label="Gantt chart: {instance.n_tasks} tasks on {instance.n_robots} robots, '
        f'makespan {schedule.makespan:g} min">',
        f"<style>{STYLE}</style>",
        # Idle is hatched, so it reads apart from the shift behind it in any palette.
        '<defs><pattern id="idle-hatch" width="6" height="6" patternUnits="userSpaceOnUse" '
        'patternTransform="rotate(45)"><rect width="6" height="6" fill="#e3e7ee"/>'
        '<line x1="0" y1="0" x2="0" y2="6" stroke="#9aa3b0" stroke-width="2"/></pattern>'
        "</defs>",
    ]
    step = _tick_step(span)
    for k in range(int(span // step) + 1):
        x = GUTTER + k * step * scale
        if x > WIDTH - 40:  # no room for its label
            break
        out.append(
            f'<line class="axis" x1="{_n(x)}" y1="{TOP - 6}" x2="{_n(x)}" '
            f'y2="{TOP + LANE * instance.n_robots}"/>'
            f'<text x="{_n(x + 2)}" y="{TOP - 10}">{_minutes_label(k * step)}</text>'
        )
    for r, lane in enumerate(lanes(problem, schedule)):
        robot = instance.robots[r]
        y = TOP + r * LANE
        bar_y = y + (LANE - BAR) / 2
        a, b = tm.shifts[r]
        shift_end = min(b, span)
        out.append(
            f'<g class="robot" data-robot={quoteattr(robot.name)}>'
            f'<rect class="lane" x="{GUTTER}" y="{y}" width="{WIDTH - GUTTER - 10}" '
            f'height="{LANE - 2}"/>'
            f'<text x="6" y="{_n(y + LANE / 2 + 4)}">{escape(robot.display)}</text>'
        )
        if shift_end > a:
            out.append(
                f'<rect class="shift" x="{_n(GUTTER + a * scale)}" y="{_n(bar_y)}" '
                f'width="{_n((shift_end - a) * scale)}" height="{BAR}"/>'
            )
        for kind in (LaneKind.IDLE, LaneKind.TRAVEL):
            items = [it for it in lane if it.kind is kind]
            if items:
                out.append(
                    f'<path class="{kind.value}" d="{_path(items, GUTTER, scale, bar_y)}">'
                    f"<title>{kind.value}: {sum(it.end - it.start for it in items):g} min"
                    "</title></path>"
                )
        for it in lane:
            if it.kind is LaneKind.TASK and it.task is not None:
                out.append(_bar(problem, schedule, it.task, critical, scale, bar_y))
        out.append("</g>")
    out.extend(_team_links(problem, schedule, scale))
    out.extend(_links(problem, schedule, scale))  # after the lanes, whose backgrounds are opaque
    end_x = GUTTER + schedule.makespan * scale
    bottom = TOP + LANE * instance.n_robots
    out.append(
        f'<line class="end" x1="{_n(end_x)}" y1="{TOP - 6}" x2="{_n(end_x)}" y2="{bottom}">'
        f"<title>makespan {schedule.makespan:g} min</title></line>"
    )
    out.append(_legend(bottom + 12))
    out.append("</svg>")
    return "".join(out)


def _bar(
    problem: Problem,
    schedule: Schedule,
    t: int,
    critical: frozenset[int],
    scale: float,
    y: float,
) -> str:
    slot, task = schedule.slots[t], problem.instance.tasks[t]
    robot = problem.instance.robots[slot.robot]
    x, width = GUTTER + slot.start * scale, max((slot.end - slot.start) * scale, 0.5)
    when = f"{slot.start:g}-{slot.end:g} min"
    start_at, end_at = schedule.wall_clock(slot.start), schedule.wall_clock(slot.end)
    if start_at and end_at:
        when += f" ({start_at[11:16]}-{end_at[11:16]})"
    hover = f"{task.id} {task.name} on {robot.name}: {when}"
    if slot.team:  # the same title in every member's lane
        names = [problem.instance.robots[m].name for m in slot.team]
        units = problem.instance.units[t]
        team = ", ".join(f"{n} ({f})" for n, f in zip(names, units, strict=True))
        hover = f"{task.id} {task.name} by a team of {len(names)}, {team}: {when}"
    if slot.zone is not None:
        hover += f", zone {slot.zone}"
    if slot.travel and not slot.team:
        hover += f", after {slot.travel:g} min travel"
    classes = "task critical" if t in critical else "task"
    if slot.team:
        classes += " team"
    if t in critical:
        hover += ", critical path"
    label = ""
    if width >= LABEL_MIN_PX:
        label = (
            f'<text class="bar-label" x="{_n(x + 3)}" y="{_n(y + BAR / 2 + 3)}">'
            f"{escape(str(task.id))[:8]}</text>"
        )
    return (
        f'<rect class="{classes}" data-task={quoteattr(str(task.id))} x="{_n(x)}" '
        f'y="{_n(y)}" width="{_n(width)}" height="{BAR}"><title>{escape(hover)}</title></rect>'
        f"{label}"
    )


def _team_links(problem: Problem, schedule: Schedule, scale: float) -> list[str]:
    """Per team task, a vertical line from its first to its last member's bar."""
    out = []
    tasks = problem.instance.tasks
    for slot in schedule.slots:
        if not slot.team:
            continue
        lanes_y = sorted(TOP + r * LANE + (LANE - BAR) / 2 for r in slot.team)
        x = GUTTER + slot.start * scale + 1
        out.append(
            f'<line class="team-link" data-task={quoteattr(str(tasks[slot.task].id))} '
            f'x1="{_n(x)}" y1="{_n(lanes_y[0] + BAR)}" x2="{_n(x)}" y2="{_n(lanes_y[-1])}">'
            f"<title>team of {len(slot.team)}</title></line>"
        )
    return out


def _links(problem: Problem, schedule: Schedule, scale: float) -> list[str]:
    """Per link type, one path of arrows and one of their heads (a 1,000-task chart stays
    light: two elements per type, not one per link), the links in task order and each task's
    `after` order. An arrow leaves the predecessor's tied end by STUB px, runs along the
    successor lane's margin and enters its bar from outside: from the left into a start, from
    the right into an end."""
    lines: dict[str, list[str]] = {kind: [] for kind in LINK_ENDS}
    heads: dict[str, list[str]] = {kind: [] for kind in LINK_ENDS}
    slots = schedule.slots
    for t, arcs in enumerate(problem.instance.timing.links):
        succ = slots[t]
        for arc in arcs:
            pred = slots[arc.pred]
            from_end, to_end = LINK_ENDS[arc.type]
            x1 = GUTTER + (pred.end if from_end else pred.start) * scale
            x2 = GUTTER + (succ.end if to_end else succ.start) * scale
            y1 = TOP + pred.robot * LANE + LANE / 2
            y2 = TOP + succ.robot * LANE + LANE / 2
            out_x = x1 + STUB if from_end else x1 - STUB
            side = 1 if to_end else -1  # where it comes from: right of an end, left of a start
            # The long run goes along the successor lane's margin (above its bars when it
            # comes from above or the same lane, below them from below), not through bars.
            margin = (LANE - BAR) / 2 - 1
            edge = y2 - BAR / 2 - margin if pred.robot <= succ.robot else y2 + BAR / 2 + margin
            lines[arc.type].append(
                f"M{_n(x1)} {_n(y1)}H{_n(out_x)}V{_n(edge)}H{_n(x2 + side * STUB)}"
                f"V{_n(y2)}H{_n(x2)}"
            )
            heads[arc.type].append(f"M{_n(x2)} {_n(y2)}l{side * 4} -3v6z")
    out = []
    for kind, drawn in lines.items():
        if drawn:
            css = f"link link-{kind.lower()}"
            out.append(
                f'<path class="{css}" data-type="{kind}" d="{"".join(drawn)}">'
                f"<title>{len(drawn)} {kind} link(s)</title></path>"
                f'<path class="link-head" data-type="{kind}" d="{"".join(heads[kind])}"/>'
            )
    return out


def _legend(y: float) -> str:
    entries = (
        ("task", "task"),
        ("task critical", "critical path"),
        ("travel", "travel"),
        ("idle", "idle"),
        ("shift", "shift"),
    )
    parts = ['<g class="legend">']
    x = GUTTER
    for css, label in entries:
        parts.append(
            f'<rect class="{css}" x="{x}" y="{_n(y)}" width="14" height="10"/>'
            f'<text x="{x + 18}" y="{_n(y + 9)}">{label}</text>'
        )
        x += 40 + 7 * len(label)
    parts.append("</g>")
    return "".join(parts)
