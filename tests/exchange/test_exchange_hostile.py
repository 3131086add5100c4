"""Hostile and wrong schedule files (app.exchange): refused whole, fast, with a typed error
saying what was expected and what was found (docs/exchange.md#bad-files)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from app.domain.errors import DomainError
from app.exchange import ExchangeError, read_mspdi, read_schedule, read_xer

NS = "http://schemas.microsoft.com/project"


def mspdi(tasks: str, head: str = "") -> bytes:
    return (
        f'<?xml version="1.0"?>{head}<Project xmlns="{NS}"><Name>P</Name>'
        f"<StartDate>2026-03-02T08:00:00</StartDate><Tasks>{tasks}</Tasks></Project>"
    ).encode()


def task(uid: int, hours: int = 1, links: str = "", features: str = "f") -> str:
    return (
        f"<Task><UID>{uid}</UID><Name>T{uid}</Name><Duration>PT{hours}H0M0S</Duration>"
        f"{links}<ExtendedAttribute><FieldID>188743731</FieldID><Value>{features}</Value>"
        "</ExtendedAttribute></Task>"
    )


def link(pred: int, kind: int = 1, lag_tenths: int = 0, extra: str = "") -> str:
    return (
        f"<PredecessorLink><PredecessorUID>{pred}</PredecessorUID><Type>{kind}</Type>"
        f"<LinkLag>{lag_tenths}</LinkLag><LagFormat>3</LagFormat>{extra}</PredecessorLink>"
    )


def test_an_external_entity_reads_nothing_from_disk(tmp_path: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP-SECRET-42")
    head = f'<!DOCTYPE Project [<!ENTITY x SYSTEM "file://{secret}">]>'
    data = mspdi(task(1).replace("<Name>T1</Name>", "<Name>&x;</Name>"), head)
    with pytest.raises(ExchangeError) as caught:
        read_mspdi(data)
    assert caught.value.code == "unsafe_xml"
    assert "TOP-SECRET" not in str(caught.value)
    assert "document type" in caught.value.message


def test_a_billion_laughs_file_is_refused_within_a_second() -> None:
    entities = '<!ENTITY lol0 "lol">' + "".join(
        f'<!ENTITY lol{i} "{f"&lol{i - 1};" * 10}">' for i in range(1, 10)
    )
    data = mspdi(
        task(1).replace("<Name>T1</Name>", "<Name>&lol9;</Name>"),
        f"<!DOCTYPE Project [{entities}]>",
    )
    began = time.perf_counter()
    with pytest.raises(ExchangeError) as caught:
        read_schedule(data)
    assert time.perf_counter() - began < 1.0
    assert caught.value.code == "unsafe_xml"


@pytest.mark.parametrize(
    ("data", "found"),
    [
        (b'{"tasks": []}', "JSON"),
        (b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1rest of an mpp", ".mpp"),
        (b"PK\x03\x04zip", "ZIP"),
        (b"%PDF-1.7", "PDF"),
        (b"Task,Duration\nPour,8h\n", "text starting 'Task,Duration"),
        (b"", "an empty body"),
    ],
)
def test_an_undetectable_format_says_what_was_expected_and_found(data: bytes, found: str) -> None:
    with pytest.raises(ExchangeError) as caught:
        read_schedule(data)
    assert caught.value.code == "wrong_format"
    assert "MSPDI" in caught.value.message and "XER" in caught.value.message
    assert found in caught.value.message
    assert isinstance(caught.value, DomainError) and caught.value.status_code == 422


def test_a_named_format_the_body_is_not_is_refused() -> None:
    xer = b"ERMHDR\t20.12\n%T\tPROJECT\n%F\tproj_id\n%R\t1\n%E\n"
    with pytest.raises(ExchangeError, match=r"expected an MSPDI file.*found an XER file"):
        read_schedule(xer, format="mspdi")
    with pytest.raises(ExchangeError, match=r"expected an XER file.*found XML"):
        read_schedule(mspdi(task(1)), format="xer")
    with pytest.raises(ExchangeError, match="root is <html>"):
        read_mspdi(b"<html><body>not a schedule</body></html>")
    with pytest.raises(ExchangeError, match="ERMHDR"):
        read_xer(b"not an xer")


def test_malformed_xml_names_where() -> None:
    with pytest.raises(ExchangeError) as caught:
        read_mspdi(mspdi(task(1))[:-20])
    assert caught.value.code == "malformed" and "line 1" in caught.value.message


def test_a_cycle_no_schedule_can_meet_is_refused_naming_it() -> None:
    # T1 -> T2 -> T3 -> T1, all finish to start: durations alone make it impossible.
    data = mspdi(task(1, links=link(3)) + task(2, links=link(1)) + task(3, links=link(2)))
    with pytest.raises(ExchangeError) as caught:
        read_mspdi(data)
    assert caught.value.code == "link_cycle" and caught.value.field == "links"
    for uid in ("1", "2", "3"):
        assert f"{uid} (FS" in caught.value.message


def test_every_cycle_is_refused_even_one_whose_lags_leave_room() -> None:
    # Two start-to-start links, lag 0, say "start together": a schedule exists, but a plan
    # places each task after its predecessors, and P6 and MS Project refuse such a file
    # themselves; /allocate refuses the same cycle (docs/schedules.md#links).
    data = mspdi(task(1, links=link(2, kind=3)) + task(2, links=link(1, kind=3)))
    with pytest.raises(ExchangeError) as caught:
        read_mspdi(data)
    assert caught.value.code == "link_cycle"
    assert "1 (SS +0 min)" in caught.value.message and "2 (SS +0 min)" in caught.value.message
    # A task linked to itself is the shortest cycle.
    with pytest.raises(ExchangeError, match=r"cycle: 1 \(FS"):
        read_mspdi(mspdi(task(1, links=link(1)) + task(2)))


def test_cross_project_and_dangling_links_are_skipped_with_why() -> None:
    other = "<CrossProject>1</CrossProject><CrossProjectName>Tower B</CrossProjectName>"
    data = mspdi(task(1, links=link(99)) + task(2, links=link(1, extra=other)))
    draft = read_mspdi(data)
    whys = [s["why"] for s in draft.skipped if s["kind"] == "link"]
    assert any("UID 99" in w and "not in the file" in w for w in whys)
    assert any("Tower B" in w for w in whys)
    assert all(t["after"] == [] for t in draft.tasks)


XER_TWO_PROJECTS = "\n".join(
    [
        "ERMHDR\t20.12",
        "%T\tPROJECT",
        "%F\tproj_id\tproj_short_name\tplan_start_date",
        "%R\t1\tA\t2026-03-02 08:00",
        "%R\t2\tB\t2026-03-02 08:00",
        "%T\tTASK",
        "%F\ttask_id\tproj_id\ttask_code\ttask_name\ttask_type\ttarget_drtn_hr_cnt",
        "%R\t10\t1\tA100\tPour\tTT_Task\t8",
        "%R\t11\t1\tA110\tCure\tTT_Task\t2",
        "%R\t20\t2\tB100\tOther pour\tTT_Task\t8",
        "%T\tTASKPRED",
        "%F\ttask_pred_id\ttask_id\tpred_task_id\tproj_id\tpred_proj_id\tpred_type\tlag_hr_cnt",
        "%R\t1\t11\t20\t1\t2\tPR_FS\t0",
        "%R\t2\t11\t30\t1\t3\tPR_SS\t1",
        "%R\t3\t11\t10\t1\t1\tPR_SF\t-0.5",
        "%E",
    ]
).encode("cp1252")


def test_xer_links_to_other_projects_are_skipped_with_why() -> None:
    draft = read_xer(XER_TWO_PROJECTS, default_features="work")
    assert [t["id"] for t in draft.tasks] == ["A100", "A110"]
    assert draft.tasks[1]["after"] == [{"task": "A100", "type": "SF", "lag": -30}]
    whys = [s["why"] for s in draft.skipped if s["kind"] == "link"]
    assert len(whys) == 2
    assert any("another project" in w for w in whys)
    assert any("not in the file" in w for w in whys)


def test_no_entity_but_xmls_own_without_a_dtd_and_no_dtd_after_the_root() -> None:
    # Without a DTD an entity reference other than XML's five is not well-formed, and a
    # document type declaration inside the root element is refused by the parser itself.
    with pytest.raises(ExchangeError) as caught:
        read_mspdi(mspdi(task(1).replace("<Name>T1</Name>", "<Name>&x;</Name>")))
    assert caught.value.code == "malformed"
    late = mspdi(task(1)).replace(b"<Tasks>", b'<Tasks><!DOCTYPE x [<!ENTITY y "z">]>')
    with pytest.raises(ExchangeError) as caught:
        read_mspdi(late)
    assert caught.value.code == "malformed"
    # XML's own entities are text as usual.
    named = read_mspdi(mspdi(task(1).replace("<Name>T1</Name>", "<Name>A &amp; B</Name>")))
    assert named.tasks[0]["name"] == "A & B"
