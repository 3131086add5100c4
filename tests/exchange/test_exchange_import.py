"""Reading schedules (app.exchange): files written by MPXJ, the independent oracle, in both
formats for one project, import to the same draft (docs/exchange.md)."""

from __future__ import annotations

from typing import Any

import pytest

from app.exchange import read_mspdi, read_schedule, read_xer
from tests.support.exchange_support import files

pytestmark = pytest.mark.usefixtures("mpxj")


def by_name(draft: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {t["name"]: t for t in draft["tasks"]}


def test_mspdi_and_xer_of_one_project_import_to_the_same_draft() -> None:
    mspdi = read_mspdi(files()["mspdi"], features_field="Text1")
    xer = read_xer(files()["xer"], features_field="Features")
    assert mspdi.request() == xer.request()
    tasks = by_name(mspdi.to_dict())
    ids = {name: t["id"] for name, t in tasks.items()}
    # Durations in working minutes; ids the file's (UID = task_code here).
    assert {n: t["duration"] for n, t in tasks.items()} == {
        "Formwork": 480,
        "Pour": 240,
        "Screed": 180,
        "Trowel": 120,
        "Inspect": 60,
        "Strip": 150,
        "Lift rebar": 120,
    }
    assert tasks["Pour"]["after"] == [{"task": ids["Formwork"], "type": "FS", "lag": 30}]
    assert tasks["Screed"]["after"] == [{"task": ids["Pour"], "type": "SS", "lag": 20}]
    assert tasks["Trowel"]["after"] == [{"task": ids["Screed"], "type": "FF", "lag": -15}]
    assert tasks["Inspect"]["after"] == [{"task": ids["Trowel"], "type": "SF", "lag": 60}]
    # The milestone is gone and bridged: its predecessor's link and its own lags add up.
    assert tasks["Strip"]["after"] == [{"task": ids["Inspect"], "type": "FS", "lag": 15}]
    assert tasks["Pour"]["features"] == ["pour", "heavy"]
    assert tasks["Formwork"]["release"] == 60  # start no earlier than 09:00, from 08:00
    assert tasks["Inspect"]["deadline"] == 33 * 60  # finish no later than 17:00 next day
    assert tasks["Lift rebar"]["planned_robots"] == ["Crane", "Hoist"]
    # Two resources on one feature: a team of two (docs/allocation.md#teams), as a request
    # sends it; one resource or several features: no team.
    assert tasks["Lift rebar"]["team"] == {"lift": 2}
    assert tasks["Lift rebar"]["features"] == ["lift"]
    assert [n for n, t in tasks.items() if "team" in t] == ["Lift rebar"]
    assert [r["name"] for r in mspdi.robots] == ["Crane", "Pump", "Screeder", "Scanner", "Hoist"]
    assert all(r["success"] == {} for r in mspdi.robots)
    assert mspdi.start == "2026-03-02T08:00:00+00:00"


@pytest.mark.parametrize("fmt", ["mspdi", "xer"])
def test_what_is_skipped_is_listed_with_why(fmt: str) -> None:
    draft = read_schedule(files()[fmt])
    skipped = {(s["kind"], s.get("name")): s["why"] for s in draft.skipped}
    assert "milestone" in skipped[("activity", "Slab ready")]
    assert "features" in skipped[("activity", "Sweep")]
    assert not any(kind == "team" for kind, _ in skipped)
    # Sweep's link from Strip goes with it, said so.
    (link,) = [s for s in draft.skipped if s["kind"] == "link"]
    assert "not imported" in link["why"]
    assert draft.source["format"] == fmt
    assert draft.source["calendar"] == "Standard"
    assert draft.source["imported"] == {"tasks": 7, "links": 6, "robots": 5}
    assert any("continuous minutes" in c for c in draft.source["caveats"])


@pytest.mark.parametrize("fmt", ["mspdi", "xer"])
def test_default_features_take_a_task_without_any(fmt: str) -> None:
    draft = read_schedule(files()[fmt], default_features="clean")
    assert by_name(draft.to_dict())["Sweep"]["features"] == ["clean"]
    assert by_name(draft.to_dict())["Pour"]["features"] == ["pour", "heavy"]


def test_the_features_field_is_found_by_its_alias_and_a_wrong_one_is_named() -> None:
    by_alias = read_mspdi(files()["mspdi"], features_field="features")
    assert by_alias.request() == read_mspdi(files()["mspdi"], features_field="Text1").request()
    from app.exchange import ExchangeError

    for reader in (read_mspdi, read_xer):
        with pytest.raises(ExchangeError) as caught:
            reader(files()["mspdi" if reader is read_mspdi else "xer"], features_field="Colour")
        assert caught.value.field == "features_field"
        assert "Features" in caught.value.message
