"""The one way tests wait for something to happen: poll until it has, or fail saying what
never happened and what was seen last. No test waits with a fixed sleep.

    state = eventually(lambda: client.get(url).json(), until=is_done, what="run done")
    eventually(lambda: point.message() in caplog.messages, what="the run held")

`wait_until` (a run over an in-process TestClient reaching a status) and `wait_logged`
(a message reaching pytest's caplog) are the two waits most tests need, built on it.

Polls come quickly at first (10 ms apart) and then further apart, up to `interval`: a
state reached at once is seen at once, and a long wait does not cost the CPU it waits on.
A poll is not free: GET /runs/{id} of a 36-task run costs about 10 ms of CPU, taken from
the run itself in an in-process TestClient (one GIL), so polling every 20 ms doubled the
CPU a test spent on a run.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, TypeVar

import pytest
from fastapi.testclient import TestClient

from app.domain.lifecycle import ACTIVE, RunStatus

T = TypeVar("T")

TIMEOUT_S = 60.0
INTERVAL_S = 0.1  # the longest pause between two polls, reached by backing off
FIRST_INTERVAL_S = 0.01
BACKOFF = 1.5  # each pause half as long again as the one before, up to `interval`
# Statuses no worker is executing (or about to): completed, failed, cancelled, interrupted.
SETTLED = tuple(s.value for s in RunStatus if s not in ACTIVE)
_SHOWN = 1500  # characters of the last value kept from each end in a failure message


def eventually(
    probe: Callable[[], T],
    *,
    what: str,
    until: Callable[[T], object] = bool,
    timeout: float = TIMEOUT_S,
    interval: float = INTERVAL_S,
    context: Callable[[], str] | None = None,
) -> T:
    """Call `probe` until `until` holds for what it returned (by default: until it returns
    something truthy), and return that value. The first pause is 10 ms (or `interval`, if
    shorter), and each next one half as long again, up to `interval` seconds.

    After `timeout` seconds the test fails with an AssertionError naming `what` (the thing
    that never happened), the last value seen and, if given, `context()` (text that is only
    worth reading on failure, such as a server log's tail). An assertion inside `probe` or
    `until` fails the test at once: use it for states from which the awaited one can no
    longer be reached.
    """
    deadline = time.monotonic() + timeout
    pause = min(FIRST_INTERVAL_S, interval)
    while True:
        value = probe()
        if until(value):
            return value
        if time.monotonic() >= deadline:
            message = f"never happened within {timeout:g} s: {what}; last seen: {_shown(value)}"
            if context is not None:
                message += f"\n{context()}"
            raise AssertionError(message)
        time.sleep(pause)
        pause = min(pause * BACKOFF, interval)


def _shown(value: object) -> str:
    text = repr(value)
    if len(text) <= 2 * _SHOWN:
        return text
    return f"{text[:_SHOWN]} ... {text[-_SHOWN:]}"


def wait_until(
    client: TestClient,
    run_id: str,
    statuses: tuple[str, ...] = SETTLED,
    *,
    timeout: float = 90,
    headers: dict[str, str] | None = None,
) -> dict[str, Any]:
    """The run's state (GET /runs/{id}) once its status is one of `statuses`."""
    state: dict[str, Any] = eventually(
        lambda: client.get(f"/runs/{run_id}", headers=headers).json(),
        until=lambda state: state["status"] in statuses,
        timeout=timeout,
        what=f"run {run_id} reached {' or '.join(statuses)}",
    )
    return state


def wait_logged(
    caplog: pytest.LogCaptureFixture, text: str, *, count: int = 1, timeout: float = TIMEOUT_S
) -> None:
    """Until `count` captured log messages contain `text` (logged from any thread, e.g. a
    run held at a test pause point: app.graph.pause.PausePoint.message())."""
    eventually(
        lambda: sum(text in message for message in caplog.messages),
        until=lambda seen: seen >= count,
        timeout=timeout,
        what=f"{count} log message(s) containing {text!r}",
    )
