"""Time in living plans against the real server (docs/living-plans.md#a-revision-in-time, issue 22's
acceptance): a timed `baseline_timed` run completes; the site reports tasks 0-10 started or done at
given times, one of them 25 minutes late; the run's schedule moves what waits for it; then, with the
heavy robot down and one task delayed 30 minutes, `ltaa revise --now ... --delay ...`
revises it over HTTP. The revision keeps the reported times, starts nothing before
`now`, moves the successors, and the diff shows it: all checked here from the rules of
docs/living-plans.md#time-in-living-plans (tests/support/time_rules.py), not by the app's own
check. A SIGKILL while the revision runs changes nothing: the revision restarted from its
checkpoint plans the same schedule."""

from __future__ import annotations

import os
import subprocess
import sys
from datetime import timedelta
from pathlib import Path
from typing import Any

import httpx
import pytest

from app.domain.catalog import timed_scenario
from app.domain.serialize import instance_to_dict
from app.graph.pause import PausePoint
from tests.support.server import ROOT, Server
from tests.support.time_rules import TimeRules, site_history, slots_of

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(900)]

INSTANCE = timed_scenario("baseline_timed").instance
START = INSTANCE.start
TASKS = instance_to_dict(INSTANCE)["tasks"]
SUCCESSORS = {
    str(p["id"]): [str(t["id"]) for t in TASKS if p["id"] in t.get("after", ())] for p in TASKS
}
LATE_BY = 25.0
DELAY = 30.0


def at(minute: float) -> str:
    assert START is not None
    return (START + timedelta(minutes=minute)).isoformat()


def finished(state: dict[str, Any]) -> bool:
    assert state["status"] not in ("failed", "cancelled"), state
    return state["status"] == "completed"


def schedule(c: httpx.Client, run_id: str) -> dict[str, Any]:
    response = c.get(f"/runs/{run_id}/schedule")
    assert response.status_code == 200, response.text
    return dict(response.json())


def ltaa_revise(server: Server, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", "from app.cli import main; main()", "revise", *args],
        cwd=ROOT,
        env={**os.environ, "LTAA_URL": server.url, "COLUMNS": "200"},
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_a_revision_at_now_after_reports_keeps_them_and_moves_the_rest(tmp_path: Path) -> None:
    data = tmp_path / "data"
    # The revision's graph holds before reasoning about task 20 (not pinned: only tasks
    # 0-10 were reported); the parent has completed before the pause is set.
    pause = PausePoint(20, "reason", after=False)
    server = Server(data).start()
    try:
        with server.client() as c:
            created = c.post("/runs", json={"scenario": "baseline_timed", "reasoner": "rules"})
            assert created.status_code == 202, created.text
            parent = created.json()["id"]
            server.wait_for(parent, finished)
            planned = schedule(c, parent)
            reported = [str(t.id) for t in INSTANCE.tasks[:11]]
            history = site_history(planned, reported, SUCCESSORS, START, LATE_BY)
            sent = c.post(f"/runs/{parent}/execution", json={"updates": history.updates})
            assert sent.status_code == 200, sent.text
            current = schedule(c, parent)
    finally:
        server.stop()

    # The parent's current schedule: reports are the truth, what waits for the late task
    # moved, nobody changed robot.
    before, moved_view = slots_of(planned), slots_of(current)
    late_end = history.reports[history.late].end
    assert late_end is not None
    assert {t: s[0] for t, s in moved_view.items()} == {t: s[0] for t, s in before.items()}
    assert TimeRules(parent_tasks=TASKS, reports=history.reports, now=0.0).broken(moved_view) == []
    assert all(moved_view[t][1] >= late_end for t in history.waiting)
    assert any(moved_view[t][1] > before[t][1] for t in history.waiting)

    now = max(r.start for r in history.reports.values()) + 5
    delayed = next(t for t in (str(x["id"]) for x in TASKS) if t not in reported and SUCCESSORS[t])
    server = Server(data).start(pause=pause)
    try:
        cli = ltaa_revise(
            server,
            parent,
            "--robot-unavailable",
            "heavy",
            "--delay",
            f"{delayed}:{DELAY:g}",
            "--now",
            at(now),
            "--reason",
            "heavy robot hydraulics; the delayed task runs long",
            "--no-wait",
        )
        assert cli.returncode == 0, cli.stderr
        with server.client() as c:
            revision = c.get(f"/runs/{parent}").json()["superseded_by"]
        assert revision is not None
        server.wait_for_log(pause.message())
    finally:
        server.kill()  # SIGKILL while the revision is deciding

    server = Server(data).start()
    try:
        state = server.wait_for(revision, finished)
        assert state["resumes"] == 1
        with server.client() as c:
            revised = schedule(c, revision)
            diff = c.get(f"/runs/{revision}/diff").json()
            verify = c.get(f"/runs/{revision}/trace/verify").json()
    finally:
        server.stop()

    robots = {t: s[0] for t, s in moved_view.items()}
    kept = {
        t: r
        for t, r in history.reports.items()
        if not (r.state == "started" and robots[t] == "heavy")
    }
    after = slots_of(revised)
    rules = TimeRules(
        parent_tasks=TASKS,
        reports=kept,
        now=now,
        delays={delayed: DELAY},
        unavailable={"heavy"},
        parent_robots={t: robots[t] for t in kept},
    )
    assert rules.broken(after) == []
    # Successors move: what waited for the late task (and is not a fact) waits for its
    # real end, and for now.
    for t in [*SUCCESSORS[history.late], *history.waiting]:
        if t not in kept:
            assert after[t][1] >= max(late_end, now), (t, after[t])
    # The diff shows it, against the parent's current schedule.
    moves = {str(m["task_id"]): m for m in diff["schedule"]["moves"]}
    changed = {
        t for t in after if t in moved_view and (after[t][1], after[t][2]) != moved_view[t][1:]
    }
    assert set(moves) == changed and delayed in moves
    for t, m in moves.items():
        assert (m["start_before"], m["end_before"]) == moved_view[t][1:]
        assert (m["start_after"], m["end_after"]) == after[t][1:]
        assert m["end_after_at"] == at(after[t][2])
    assert not {t for t, r in kept.items() if r.state == "done"} & set(moves)
    assert diff["schedule"]["makespan_before"]["minutes"] == current["makespan"]
    assert diff["schedule"]["makespan_after"] == {
        "minutes": revised["makespan"],
        "at": at(revised["makespan"]),
    }
    assert {c["robot"] for c in diff["fleet_changes"]} == {"heavy"}
    assert verify["ok"] is True, verify
