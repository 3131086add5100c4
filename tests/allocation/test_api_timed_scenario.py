"""The built-in timed scenario by name on every entry point that takes a scenario: /allocate
answers it with its own start and a schedule, and refuses a `start` or `travel` sent with it
(the scenario has its own), naming the field."""

from __future__ import annotations

from fastapi.testclient import TestClient

from app.domain.catalog import timed_scenario
from app.domain.serialize import instance_to_dict
from tests.support.timed_checks import feasibility_errors


def test_allocate_plans_the_timed_scenario_by_name_from_its_own_start(client: TestClient) -> None:
    response = client.post("/allocate", json={"solver": "greedy", "scenario": "baseline_timed"})
    assert response.status_code == 200, response.text
    body = response.json()
    schedule = body["schedule"]
    instance = timed_scenario("baseline_timed").instance
    assert instance.start is not None
    assert schedule["start"] == instance.start.isoformat()
    assert sorted(str(t["task_id"]) for t in schedule["tasks"]) == sorted(
        str(t.id) for t in instance.tasks
    )
    # What the service says it breaks is what the rules written from
    # docs/schedules.md#a-schedule-and-its-check find.
    own = feasibility_errors(instance_to_dict(instance), schedule)
    assert bool(own) == bool(body["schedule_violations"]), (own, body["schedule_violations"])


def test_a_start_or_travel_sent_with_the_timed_scenario_is_refused(client: TestClient) -> None:
    for field, value in (("start", "2026-03-02T08:00:00+01:00"), ("travel", {"A": {"B": 1}})):
        response = client.post(
            "/allocate", json={"solver": "greedy", "scenario": "baseline_timed", field: value}
        )
        assert response.status_code == 422, response.text
        assert field in response.text and "baseline_timed" in response.text
