"""What the console shows of a team decision (docs/allocation.md#teams): one line per unit
with the member's reason from the final attempt's **Team** block, a reason only where that
line names the same unit and member, and the run page's members through the in-process client
(tests/console/test_console_teams_browser.py drives the same page in Chromium)."""

from __future__ import annotations

import copy

from fastapi.testclient import TestClient
from pydantic import SecretStr

from app.console.views import TeamLine, team_lines
from app.store.models import Attempt
from tests.allocation.test_api_teams import TEAM_BODY
from tests.console.test_console import CLIENT, KEYS, _sign_in
from tests.support.clients import ClientFactory
from tests.support.polling import wait_until

TEAM = [{"robot": "crane", "feature": "heavy"}, {"robot": "arm", "feature": "careful"}]


def _attempt(parsed: dict[str, object] | None) -> Attempt:
    return Attempt(task_index=1, attempt=1, parsed=parsed)


def test_each_member_takes_the_reason_of_its_own_team_line() -> None:
    said = [
        {"feature": "heavy", "robot": "crane", "text": "crane", "reason": "strongest lift"},
        {"feature": "careful", "robot": "arm", "text": "arm", "reason": "steady hands"},
    ]
    assert team_lines(TEAM, _attempt({"team": said})) == [
        TeamLine("heavy", "crane", "strongest lift"),
        TeamLine("careful", "arm", "steady hands"),
    ]
    # A line naming another member (the decision fell back, or was overridden) lends no reason.
    other = [said[0], {**said[1], "robot": "lifter"}]
    assert [m.reason for m in team_lines(TEAM, _attempt({"team": other}))] == [
        "strongest lift",
        None,
    ]
    assert [m.reason for m in team_lines(TEAM, _attempt(None))] == [None, None]
    assert [m.reason for m in team_lines(TEAM, None)] == [None, None]
    assert team_lines(None, _attempt({"team": said})) == []


def test_the_run_page_lists_a_team_decisions_members(make_client: ClientFactory) -> None:
    client: TestClient = make_client(api_keys=SecretStr(KEYS))
    created = client.post(
        "/runs",
        json={**copy.deepcopy(TEAM_BODY), "reasoner": "rules"},
        headers={"X-API-Key": CLIENT},
    )
    assert created.status_code == 202, created.text
    run_id = str(created.json()["id"])
    wait_until(client, run_id, ("completed",), headers={"X-API-Key": CLIENT})
    run = client.get(f"/runs/{run_id}", headers={"X-API-Key": CLIENT}).json()
    assert _sign_in(client) == 303
    page = client.get(f"/console/runs/{run_id}?decision=0").text
    for task_index in (0, 1):
        assert f'id="team-{task_index}"' in page
        for member in run["assignments"][task_index]["team"]:
            assert f'data-feature="{member["feature"]}" data-robot="{member["robot"]}"' in page
    assert 'id="team-2"' not in page and 'id="team-3"' not in page
    # Each of the four members' sentence from the rules reasoner: `covers heavy at 90.0% ...`.
    assert page.count('class="member-reason">covers ') == 4
    loads = ", ".join(f"{name} {n}" for name, n in run["workload"].items())
    assert f"Workload per robot: {loads}." in page
