"""`ltaa revise --delay/--now` (docs/living-plans.md#the-diff-in-time): the delay change it sends,
and the time moves it prints from a diff."""

from __future__ import annotations

import pytest
from rich.console import Console

from app.cli.revise import ReviseError, build_changes, parse_delay, print_time_moves


def test_a_delay_names_the_task_and_the_minutes() -> None:
    assert parse_delay("21:30") == {"type": "delay", "task_id": 21, "minutes": 30}
    assert parse_delay("pour:7.5") == {"type": "delay", "task_id": "pour", "minutes": 7.5}
    changes = build_changes(
        unavailable=["heavy"],
        available=[],
        rates=[],
        add_next=[],
        add_end=[],
        remove=[],
        mode=None,
        max_deviation=None,
        delays=["21:30"],
    )
    assert [c["type"] for c in changes] == ["robot_unavailable", "delay"]


@pytest.mark.parametrize("text", ["21", "21:0", "21:-5", ":30", "21:soon"])
def test_a_bad_delay_says_how_to_write_it(text: str) -> None:
    with pytest.raises(ReviseError, match="<task id>:<minutes>"):
        parse_delay(text)


def test_the_time_moves_are_printed() -> None:
    console = Console(record=True, width=160)
    print_time_moves(
        {
            "moves": [
                {
                    "task_id": 7,
                    "task_name": "Look Down",
                    "robot_before": "heavy",
                    "robot_after": "light",
                    "start_before": 40,
                    "start_after": 95,
                    "end_before": 51,
                    "end_after": 101,
                    "start_moved": 55,
                    "end_moved": 50,
                }
            ],
            "makespan_before": {"minutes": 192, "at": "2026-03-02T10:12:00+01:00"},
            "makespan_after": {"minutes": 230.5, "at": "2026-03-02T10:50:30+01:00"},
        },
        console,
    )
    text = console.export_text()
    assert "makespan: 192 min (2026-03-02T10:12:00+01:00) -> 230.5 min" in text
    assert "heavy -> light" in text and "40 -> 95" in text and "+55 / +50" in text
