"""GET /runs/{id}/schedule (docs/schedules.md#reading-a-runs-schedule): a completed timed run's
schedule read as JSON, CSV and iCalendar, the same times as its assignments; an untimed run's is
a 409 saying it has no times, an unknown run's a 404."""

from __future__ import annotations

import csv
import io
from datetime import datetime

import icalendar
from fastapi.testclient import TestClient

from tests.runs.test_api_timed_runs import TIMED, all_assignments, completed


def test_a_timed_runs_schedule_reads_as_json_csv_and_icalendar(client: TestClient) -> None:
    state = completed(client, TIMED)
    run_id = state["id"]
    assignments = {a["task_id"]: a for a in all_assignments(client, run_id)}
    schedule = client.get(f"/runs/{run_id}/schedule")
    assert schedule.status_code == 200, schedule.text
    block = schedule.json()
    assert len(block["tasks"]) == 36
    for task in block["tasks"]:
        a = assignments[task["task_id"]]
        assert (task["robot"], task["start"], task["end"]) == (a["robot"], a["start"], a["end"])
    assert block["makespan"] == max(a["end"] for a in assignments.values())
    assert set(block["robots"]) == {"light", "medium", "heavy"}

    table = client.get(f"/runs/{run_id}/schedule", params={"format": "csv"})
    assert table.status_code == 200 and table.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(table.text)))
    assert len(rows) == 36
    assert {str(r["task_id"]) for r in rows} == {str(t) for t in assignments}

    ics = client.get(f"/runs/{run_id}/schedule", params={"format": "ics"})
    assert ics.status_code == 200 and ics.headers["content-type"].startswith("text/calendar")
    calendar = icalendar.Calendar.from_ical(ics.content)
    events = list(calendar.walk("VEVENT"))
    assert len(events) == 36
    starts = sorted(e.decoded("DTSTART") for e in events)
    first = min(assignments.values(), key=lambda a: a["start"])
    assert starts[0] == datetime.fromisoformat(first["start_at"])


def test_an_untimed_runs_schedule_is_a_409_saying_it_has_no_times(client: TestClient) -> None:
    state = completed(client, {"scenario": "baseline"})
    response = client.get(f"/runs/{state['id']}/schedule")
    assert response.status_code == 409, response.text
    (error,) = response.json()["detail"]
    assert "has no times" in error["msg"] and "untimed" in error["msg"]
    missing = client.get("/runs/nosuchrun/schedule")
    assert missing.status_code == 404
