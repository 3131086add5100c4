"""The Gantt chart's link arrows (docs/schedules.md#the-consoles-gantt-chart): each typed link
(docs/schedules.md#links) is an arrow from the predecessor's right end (FS, FF) or left end (SS,
SF) to the successor's start (FS, SS) or end (FF, SF), lane to lane, read here from the SVG
against the schedule's own times."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from datetime import UTC, datetime

import pytest

from app.domain.links import Link
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.schedule_views import gantt_svg
from app.schedule_views.gantt import BAR, GUTTER, LANE, TOP, WIDTH
from app.solvers.registry import get_solver

SVG = "{http://www.w3.org/2000/svg}"


def problem() -> Problem:
    def task(tid: str, features: str, minutes: int, after: Link | str | None = None) -> Task:
        return Task(
            id=tid,
            name=tid.title(),
            features=(features,),
            duration=minutes,
            after=() if after is None else (after,),
        )

    tasks = (
        task("pour", "h", 30),
        task("fs", "h", 10, Link("pour", lag=5)),
        task("ss", "c", 20, Link("pour", "SS", 10)),
        task("ff", "c", 15, Link("pour", "FF")),
        task("sf", "h", 12, Link("pour", "SF", 40)),
        Task(id="beam", name="Beam", features=("h",), team={"h": 2}, duration=8, after=("fs",)),
    )
    robots = (
        Robot(name="a", success={"h": 0.9, "c": 0.2}),
        Robot(name="b", success={"h": 0.5, "c": 0.9}),
        Robot(name="c", success={"h": 0.7, "c": 0.6}),
    )
    instance = Instance(tasks=tasks, robots=robots, start=datetime(2026, 3, 2, 7, tzinfo=UTC))
    return Problem.build(instance, Mode.SUCCESS_FOCUSED)


def subpaths(d: str) -> list[list[float]]:
    return [[float(x) for x in re.findall(r"-?\d+(?:\.\d+)?", part)] for part in d.split("M")[1:]]


def test_each_link_is_an_arrow_between_the_ends_its_type_ties() -> None:
    p = problem()
    schedule = get_solver("optimal").solve(p).details["schedule"]
    root = ET.fromstring(gantt_svg(p, schedule))
    scale = (WIDTH - GUTTER - 10) / max(schedule.makespan, 1.0)
    paths = list(root.iter(f"{SVG}path"))
    lines = {e.get("data-type"): e for e in paths if (e.get("class") or "").startswith("link ")}
    heads = {e.get("data-type"): e for e in paths if e.get("class") == "link-head"}
    assert set(lines) == set(heads) == {"FS", "SS", "FF", "SF"}
    ends = {
        "FS": ("end", "start"),
        "SS": ("start", "start"),
        "FF": ("end", "end"),
        "SF": ("start", "end"),
    }
    links = p.instance.timing.links
    for kind, element in lines.items():
        assert kind is not None
        assert element.get("class") == f"link link-{kind.lower()}"
        # The links of this type, in task order: the chart's subpaths, one arrow each.
        pairs = [(arc.pred, t) for t, arcs in enumerate(links) for arc in arcs if arc.type == kind]
        drawn = subpaths(element.get("d") or "")
        tips = subpaths(heads[kind].get("d") or "")
        assert len(drawn) == len(tips) == len(pairs)
        at_pred, at_succ = ends[kind]
        for (u, t), path, tip in zip(pairs, drawn, tips, strict=True):
            x1, y1, out_x, edge, before, y2, x2 = path
            pred, succ = schedule.slots[u], schedule.slots[t]
            # The long run in the successor lane's margin, outside its bars.
            bar_top, bar_bottom = y2 - BAR / 2, y2 + BAR / 2
            assert edge < bar_top or edge > bar_bottom
            assert abs(edge - y2) < LANE / 2
            assert x1 == pytest.approx(GUTTER + getattr(pred, at_pred) * scale, abs=0.06)
            assert x2 == pytest.approx(GUTTER + getattr(succ, at_succ) * scale, abs=0.06)
            assert y1 == pytest.approx(TOP + pred.robot * LANE + LANE / 2, abs=0.06)
            assert y2 == pytest.approx(TOP + succ.robot * LANE + LANE / 2, abs=0.06)
            # Out of the predecessor's tied end, into the successor's bar from outside.
            assert (out_x > x1) if at_pred == "end" else (out_x < x1)
            assert (before < x2) if at_succ == "start" else (before > x2)
            # The head's tip is the arrow's end, its base on the side the arrow comes from.
            assert tip[:2] == [x2, y2] and (tip[2] < 0) == (at_succ == "start")
        title = element.find(f"{SVG}title")
        assert title is not None and title.text == f"{len(pairs)} {kind} link(s)"
    assert len(subpaths(lines["FS"].get("d") or "")) == 2  # pour -> fs, fs -> the team task


def test_a_chart_without_links_draws_no_arrow() -> None:
    p = problem()
    plain = Instance(
        tasks=tuple(
            t.__class__(id=t.id, name=t.name, features=t.features, duration=10)
            for t in p.instance.tasks[:3]
        ),
        robots=p.instance.robots,
    )
    q = Problem.build(plain, Mode.SUCCESS_FOCUSED)
    svg = gantt_svg(q, get_solver("greedy").solve(q).details["schedule"])
    assert 'class="link ' not in svg
