"""The built-in timed scenario and the generator of timed construction instances."""

from __future__ import annotations

import json
from importlib import resources
from typing import Any

import pytest

from app.domain.catalog import scenario, scenarios, timed_scenario, timed_scenarios
from app.domain.errors import DomainError
from benchmarks.timed_instances import TRADES, construction_site


def _doc() -> dict[str, Any]:
    text = resources.files("app.data").joinpath("timed_scenarios.json").read_text("utf-8")
    doc: dict[str, Any] = json.loads(text)["scenarios"][0]
    return doc


def test_the_timed_scenario_is_the_paper_instance_in_time() -> None:
    assert set(scenarios()) == {"baseline", "heavy_excels", "medium_excels", "light_excels"}
    assert list(timed_scenarios()) == ["baseline_timed", "baseline_team"]
    timed = timed_scenario("baseline_timed").instance
    base = scenario("baseline").instance
    assert [(t.id, t.name, t.features) for t in timed.tasks] == [
        (t.id, t.name, t.features) for t in base.tasks
    ]
    assert (timed.success == base.success).all()
    tm = timed.timing
    assert sorted(tm.zones) == ["A", "B", "C"]
    assert timed.eligible.all()  # every robot can take every task, only at its own pace
    assert [r.zone for r in timed.robots] == ["A", "B", "C"]
    assert [r.available for r in timed.robots] == [(0, 480), (0, 480), (30, 450)]
    assert timed.start is not None and timed.start.utcoffset() is not None
    assert any(t.release for t in timed.tasks) and any(t.deadline for t in timed.tasks)
    with pytest.raises(DomainError) as err:
        timed_scenario("nope")
    assert err.value.field == "scenario" and "baseline_timed" in err.value.message


def test_durations_follow_the_documented_rule() -> None:
    doc = _doc()
    rule = doc["duration_rule"]
    rates = {r.name: r.success for r in scenario("baseline").instance.robots}
    timed = timed_scenario("baseline_timed").instance
    for task in timed.tasks:
        assert isinstance(task.duration, dict)
        for name, minutes in task.duration.items():
            pace = [rule["reference_rate"] / rates[name][f] for f in task.features]
            expected = round(rule["base_minutes"][task.type] * sum(pace) / len(pace))
            assert minutes == expected, (task.id, name)


def test_no_inspection_before_the_work_it_inspects() -> None:
    timed = timed_scenario("baseline_timed").instance
    by_id = {t.id: t for t in timed.tasks}
    check = by_id[500]  # OpenProgressCheck
    inspected = {by_id[i].type for i in check.after_ids}
    assert inspected == {"ObjectInteraction"} and len(check.after) >= 5
    assert by_id[501].after == (500,) and by_id[502].after == (501,)
    assert all(by_id[i].type == "ProgressCheck" for i in (500, 501, 502))


@pytest.mark.parametrize(("n_tasks", "n_robots"), [(36, 3), (200, 20), (1000, 20)])
def test_generated_sites_have_the_sizes_asked_for(n_tasks: int, n_robots: int) -> None:
    inst = construction_site(n_tasks, n_robots, seed=5)
    assert (inst.n_tasks, inst.n_robots) == (n_tasks, n_robots)
    assert inst.timed and len(inst.timing.zones) >= 3


def test_generated_sites_follow_the_trades_and_the_floors() -> None:
    inst = construction_site(200, 6, seed=7)
    by_id = {t.id: t for t in inst.tasks}
    trades = [t.name for t in TRADES]
    for task in inst.tasks:
        for before in task.after_ids:
            earlier = by_id[before]
            if task.zone == earlier.zone:  # the previous trade of the same package
                assert trades.index(task.type) == trades.index(earlier.type) + 1
            else:  # formwork waits for the pour of the slab below
                assert (task.type, earlier.type) == ("formwork", "pour")
                assert int(task.zone[1]) == int(earlier.zone[1]) + 1  # type: ignore[index]
    assert any(t.release for t in inst.tasks if t.type == "pour")


def test_generation_is_seeded() -> None:
    assert construction_site(60, 5, seed=1) == construction_site(60, 5, seed=1)
    assert construction_site(60, 5, seed=1) != construction_site(60, 5, seed=2)


def test_light_robots_can_be_kept_off_the_pours() -> None:
    inst = construction_site(40, 6, seed=1, light_pours=False)
    for t, task in enumerate(inst.tasks):
        for r, robot in enumerate(inst.robots):
            cannot = task.type == "pour" and robot.name.startswith("light")
            assert inst.eligible[t, r] == (not cannot)
