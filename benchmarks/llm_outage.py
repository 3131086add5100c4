"""`python -m benchmarks.llm_outage`: what a model server that is down, or answers HTTP 500 to
everything, costs a 36-task run with the default settings (docs/reasoners.md#bounded-cost),
written as its own section of docs/llm-benchmark.md.

Each case is one run of the LTAA graph with the `openai` reasoner through the real SDK,
with the service's default settings (3 transport retries with the SDK's backoff, 4 attempts
a task, given up after 3 failed tasks in a row): against a loopback port nothing listens
on, and against the test suite's fake Chat Completions server answering 500 to every
request. Wall time is measured, as are the requests sent and the task from which the rule
decided.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path

from app.config import Settings
from app.domain.modes import Mode
from app.reasoners.base import Reasoner
from app.reasoners.factory import make_reasoner
from app.reasoners.scope import LLMScope
from app.solvers.ltaa import model_use_for
from benchmarks.common import machine, table
from benchmarks.llm_live import REPORT, live_cell, write
from tests.fakes.fake_chat_completions_api import FakeChatCompletionsAPI
from tests.fakes.fake_messages_api import Reply

TITLE = "A model server that is down or answers 500 (default settings)"


def _closed_port() -> int:
    """A loopback port nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _case(name: str, base_url: str) -> list[str]:
    settings = Settings(openai_base_url=base_url, openai_model="down")
    fmt = settings.llm_reply_format

    def make(scope: LLMScope) -> Reasoner:
        return make_reasoner("openai", settings=settings, reply_format=fmt)

    started = time.perf_counter()
    cell = live_cell(
        make,
        "baseline",
        Mode.BALANCED,
        LLMScope.ALL,
        guided=False,
        model_use=model_use_for("openai", fmt, settings.llm_give_up_after),
    )
    seconds = time.perf_counter() - started
    return [
        name,
        f"{seconds:.1f}",
        "-" if cell.gave_up_at is None else str(cell.gave_up_at),
        str(cell.fallbacks),
        "-",
        f"{cell.n_tasks - cell.fallbacks}",
    ]


def main(path: Path = REPORT) -> None:
    rows = [_case("nothing listens on the port", f"http://127.0.0.1:{_closed_port()}/v1")]
    with FakeChatCompletionsAPI(default=lambda request: Reply.error(500, retry_after=None)) as api:
        row = _case("every request answered 500", api.base_url)
        row[4] = str(len(api.requests))
        rows.append(row)
    section = (
        f"## {TITLE}\n\n"
        f"**Generated:** by `python -m benchmarks.llm_outage` ({machine()}): the 36-task "
        "`baseline` in `balanced` mode, scope `all`, with the `openai` reasoner through the "
        "real SDK and the service's default settings (3 transport retries with the SDK's "
        "backoff, 4 attempts a task, `LTAA_LLM_GIVE_UP_AFTER=3`). The rule decides every "
        "task either way; what the outage costs is the wall time before it takes over.\n\n"
        + table(
            [
                "server",
                "run's wall time (s)",
                "rule decides from task",
                "fallbacks",
                "requests the server saw",
                "decided by the rule after giving up",
            ],
            rows,
        )
        + "\n"
    )
    print(f"wrote {write(section, path)}")


if __name__ == "__main__":
    main()
