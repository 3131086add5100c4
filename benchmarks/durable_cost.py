"""What durability costs (issue 21): a durable run polled as site software polls it, against
the same graph in memory, at 1,000 and 10,000 tasks, measured as the server's CPU.

One server started by scripts/serve.sh (uvicorn, one process, SQLite), per code version.
For each size: `POST /allocate` with solver `ltaa` (the graph with InMemorySaver and the
in-memory recorder: no database), then `POST /runs` (the real RunWorker, the app tables,
the SQLite checkpointer) with `GET /runs/{id}` sent every 0.5 s until it completes. CPU is
the server process's own (user + system, all threads, from /proc), from the request to
the answer (in memory) or to the poll that saw the run complete (durable): the polls run
in the server, so they are counted. Wall time is the client's.

`LTAA_BENCH_BEFORE=<path of a worktree of an older commit>` measures that code too, in the
same run, with its own server (its sources first on the path, this environment's packages);
`LTAA_BENCH_BEFORE_LABEL` says what that code is, for the report. The 1-minute load average
is sampled as each measure starts and ends: on a shared machine it says how much the
figures may have moved.
"""

from __future__ import annotations

import datetime as dt
import os
import statistics
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

from app.domain.serialize import instance_to_dict
from benchmarks.common import ROOT, Section, fmt_time, synthetic_instance, table
from benchmarks.load import serve_process

SMALL, LARGE = 1_000, 10_000
SIZES = (SMALL, LARGE)
# The order of the pairs (in memory, then durable) on one server. The small pairs bracket
# each large one, two before and two after: this shared machine's speed drifts by a fifth
# within minutes (and twofold between days), and a drift during the measure then moves
# both sides of the 10,000/1,000 ratio instead of one. Each column's median is reported.
SCHEDULE = (SMALL, SMALL, LARGE, SMALL, SMALL, LARGE, SMALL, SMALL)
ROBOTS = 4
POLL_S = 0.5
TARGET_RATIO, TARGET_SCALING = 1.5, 10.0
# Where a durable run's cost per task is read, as fractions of its tasks: the second tenth
# and the ninth (clear of the start-up and of the end), from the server's CPU and the run's
# progress at each poll.
EARLY, LATE = (0.1, 0.2), (0.8, 0.9)
CLK_TCK = os.sysconf("SC_CLK_TCK")
# The code before issue 21 (a811c7e), measured by this script on 2026-12-02 in one run
# (LTAA_BENCH_BEFORE), on this machine under a load average of 12-17: shown when the
# "before" code is not measured again.
RECORDED_BEFORE = (
    "measured on 2026-12-02 by this script, before issue 21 (a811c7e), in one run: 1,000 "
    "tasks: in memory 4.48 s CPU, durable polled 20.18 s CPU (48.9 s wall), **4.50×** "
    "(2.85× with the polls left out); 10,000 tasks: in memory 47.11 s, durable 373.12 s CPU "
    "(1,388 s wall, 570 polls), **7.92×**; the 10,000-task durable run 18.5× the CPU of the "
    "1,000-task one (28.4× its wall time)"
)


def server_cpu(pid: int) -> float:
    """User + system CPU seconds of a process, all its threads, so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


@dataclass(frozen=True)
class Measure:
    wall: float
    cpu: float
    polls: int = 0
    poll_cpu: float = 0.0  # polls x the CPU of one poll of the completed run (estimate)
    # (tasks decided, server CPU seconds since the request) at each poll of a durable run
    progress: tuple[tuple[int, float], ...] = ()

    def cpu_per_task(self, share: tuple[float, float], n_tasks: int) -> float | None:
        """The server's CPU per task decided while the run went from one share of its tasks
        to the other (polls included), from the first polls that saw each share reached;
        None when the polls were too sparse to tell."""
        marks = []
        for target in (share[0] * n_tasks, share[1] * n_tasks):
            mark = next(((t, c) for t, c in self.progress if t >= target), None)
            if mark is None:
                return None
            marks.append(mark)
        (t0, c0), (t1, c1) = marks
        return (c1 - c0) / (t1 - t0) if t1 > t0 else None


@dataclass(frozen=True)
class SizeResult:
    n_tasks: int
    memories: tuple[Measure, ...]  # in the order measured, paired with durables
    durables: tuple[Measure, ...]
    load: tuple[float, float] = (0.0, 0.0)  # lowest and highest 1-minute load average seen

    @property
    def memory(self) -> Measure:
        return _median(self.memories)

    @property
    def durable(self) -> Measure:
        return _median(self.durables)

    @property
    def ratio(self) -> float:
        return self.durable.cpu / self.memory.cpu


def _body(n: int) -> dict[str, Any]:
    data = instance_to_dict(synthetic_instance(n, ROBOTS, seed=0))
    return {"tasks": data["tasks"], "robots": data["robots"], "mode": "balanced"}


def _in_memory(client: httpx.Client, pid: int, body: dict[str, Any]) -> Measure:
    start, cpu = time.perf_counter(), server_cpu(pid)
    answer = client.post("/allocate", json={**body, "solver": "ltaa"})
    wall, used = time.perf_counter() - start, server_cpu(pid) - cpu
    if answer.status_code != 200:
        raise RuntimeError(f"/allocate answered {answer.status_code}: {answer.text[:500]}")
    return Measure(wall, used)


def _durable(client: httpx.Client, pid: int, body: dict[str, Any]) -> Measure:
    start, cpu = time.perf_counter(), server_cpu(pid)
    created = client.post("/runs", json={**body, "reasoner": "rules"})
    if created.status_code != 202:
        raise RuntimeError(f"POST /runs answered {created.status_code}: {created.text[:500]}")
    run_id = created.json()["id"]
    progress = []
    while True:
        time.sleep(POLL_S)
        state = client.get(f"/runs/{run_id}").json()
        progress.append((state["progress"]["allocated"], server_cpu(pid) - cpu))
        if state["status"] not in ("queued", "running"):
            break
    wall, used = time.perf_counter() - start, server_cpu(pid) - cpu
    if state["status"] != "completed":
        raise RuntimeError(f"benchmark run ended {state['status']}: {state.get('error')}")
    # What one poll costs, on the completed run (its page full, its metrics computed: the
    # dearest poll): an upper estimate of the polls' share.
    before = server_cpu(pid)
    for _ in range(5):
        client.get(f"/runs/{run_id}")
    per_poll = (server_cpu(pid) - before) / 5
    polls = len(progress)
    return Measure(wall, used, polls, polls * per_poll, tuple(progress))


def measure(root: Path, schedule: tuple[int, ...] = SCHEDULE) -> list[SizeResult]:
    """The pairs of `schedule` (in memory, then durable) on one server running the code
    under `root`; one result per size, smallest first."""
    env = {"LTAA_MAX_CONCURRENT_RUNS": "1"}  # the server's default logging: a line a decision
    if root != ROOT:
        env["PYTHONPATH"] = str(root)
    memories: dict[int, list[Measure]] = {}
    durables: dict[int, list[Measure]] = {}
    loads: dict[int, list[float]] = {}
    with (
        tempfile.TemporaryDirectory(prefix="ltaa-bench-cost-") as tmp,
        serve_process(Path(tmp), env, cwd=root) as (url, _log, pid),
        httpx.Client(base_url=url, timeout=3600) as client,
    ):
        bodies = {n: _body(n) for n in set(schedule)}
        for n in schedule:
            seen = loads.setdefault(n, [])
            seen.append(os.getloadavg()[0])
            memories.setdefault(n, []).append(_in_memory(client, pid, bodies[n]))
            durables.setdefault(n, []).append(_durable(client, pid, bodies[n]))
            seen.append(os.getloadavg()[0])
    return [
        SizeResult(n, tuple(memories[n]), tuple(durables[n]), (min(loads[n]), max(loads[n])))
        for n in sorted(memories)
    ]


def _median(measures: Sequence[Measure]) -> Measure:
    """Each figure's median (of an even count, the mean of the middle two); the progress
    of the measure of median CPU (of an even count, the dearer of the middle two)."""
    middle = sorted(measures, key=lambda m: m.cpu)[len(measures) // 2]
    return Measure(
        statistics.median(m.wall for m in measures),
        statistics.median(m.cpu for m in measures),
        round(statistics.median(m.polls for m in measures)),
        statistics.median(m.poll_cpu for m in measures),
        middle.progress,
    )


def _verdict(ok: bool) -> str:
    return "met" if ok else "**missed**"


def _rows(label: str, results: list[SizeResult]) -> list[list[str]]:
    rows = []
    for r in results:
        d, m = r.durable, r.memory
        rows.append(
            [
                label,
                f"{r.n_tasks:,}",
                f"{fmt_time(m.cpu)} ({fmt_time(m.wall)})",
                f"{fmt_time(d.cpu)} ({fmt_time(d.wall)})",
                f"{d.polls} ({fmt_time(d.poll_cpu)})",
                f"**{r.ratio:.2f}**",
                f"{(d.cpu - d.poll_cpu) / m.cpu:.2f}",
                f"{r.load[0]:.1f} to {r.load[1]:.1f}",
                ", ".join(
                    f"{mem.cpu / r.n_tasks * 1e3:.2f} / {dur.cpu / r.n_tasks * 1e3:.2f}"
                    for mem, dur in zip(r.memories, r.durables, strict=True)
                ),
            ]
        )
    return rows


# What the rounds of issue 21 changed, and how the measure itself changed.
_HISTORY = (
    "Issue 21's third round changed how this is measured, not the code. On 2026-12-02 "
    "the sizes were measured one after the other (three 1,000-task pairs, then one "
    "10,000-task pair) and the 10,000-task durable run came out 12.0× the 1,000-task "
    "one, the graph in memory 12.1×. Yet the same solve in one process, outside the "
    "server, cost the same per task from the first thousand tasks to the last (7.96 "
    "and 7.21 ms, no trend in between, garbage collection on or off alike), and "
    "cProfile found every function's calls and time 10× at 10× the tasks. What moved "
    "is the machine: on this shared 2-core host the same pair costs a fifth more or "
    "less minutes apart (the last column), and twice as much on one day as on another "
    "(3.45 ms a task in memory on 2026-12-02, 7.45 today), so a 10,000-task pair "
    "measured in a slower spell than the 1,000-task pairs before it reads as growth. "
    "The small pairs now bracket each large one, and the cost per task is also read "
    "inside the large runs, where no drift between runs can enter."
    + "\n\nWhat changed in issue 21's second round: a `rules` task's attempts are "
    "written with its decision, in one transaction of two statements (four "
    "transactions before: the prompt, the reply and the validation each had their "
    "own); a reply that cost, or failed, is still written the moment it arrives, and "
    "under a review policy nothing waits. A poll keeps each stored assignment as "
    "rendered (a stored decision never changes; one with an execution report is "
    "rendered every time), so it reads the page's task indexes and renders only the "
    "decisions stored since the last poll: 60 ms of CPU a poll of a completed "
    "1,000-task run became about 9. Its totals (workload, regret, usage) fold in only "
    "the decisions and attempts stored since the last poll (the run's settled prefix is "
    "kept: it never changes); aggregated in SQL they read every row's text, 30 ms a poll "
    "of a completed 10,000-task run. The graph itself (both columns): a reply's robot "
    "aliases and their patterns built once per fleet, an attempt's parsed reply "
    "copied as JSON rather than by copy.deepcopy, the next task found without copying "
    "the rest of the queue."
    + "\n\nWhat changed in its first round: each recorder write carries its fence (run still "
    "`running`; on PostgreSQL the lease) inside its one INSERT ... ON CONFLICT "
    "statement, on a plain connection, instead of three statements in an ORM session; "
    "a decision's chain link is computed from what the recorder wrote (read back only "
    "after a restart); the SQLite checkpointer writes one checkpoint where each task "
    "begins (and where the graph pauses for a review or ends) instead of one per "
    "super-step plus every node's writes; a poll reads its totals as SQL aggregates "
    "and its page as plain rows instead of every decision and attempt of the run.\n"
)


def _verdicts(after: list[SizeResult]) -> str:
    small, large = after[0], after[-1]
    scaling = large.durable.cpu / small.durable.cpu
    scaling_wall = large.durable.wall / small.durable.wall
    memory_scaling = large.memory.cpu / small.memory.cpu
    return table(
        ["target", "measured", "verdict"],
        [
            [
                f"durable ≤ {TARGET_RATIO:g}× in-memory CPU, {r.n_tasks:,} tasks (polled)",
                f"{r.ratio:.2f}×",
                _verdict(r.ratio <= TARGET_RATIO),
            ]
            for r in after
        ]
        + [
            [
                f"durable {large.n_tasks:,} tasks ≤ {TARGET_SCALING:g}× {small.n_tasks:,} tasks",
                f"{scaling:.1f}× CPU ({scaling_wall:.1f}× wall; in memory {memory_scaling:.1f}×)",
                _verdict(scaling <= TARGET_SCALING),
            ]
        ],
    )


def _before_text(before: list[SizeResult] | None) -> str:
    label = os.environ.get("LTAA_BENCH_BEFORE_LABEL", "an older commit")
    before_text = (
        f'The "before" rows are {label}, measured by the same script in the same run (its '
        "own server, one after the other: this branch's rows follow)."
        if before
        else f"Before issue 21 ({RECORDED_BEFORE})."
    )
    if before:
        b_small, b_large = before[0], before[-1]
        before_text += (
            f" Before: {b_small.ratio:.2f}× and {b_large.ratio:.2f}×, the {b_large.n_tasks:,}-task "
            f"durable run {b_large.durable.cpu / b_small.durable.cpu:.1f}× the CPU of the "
            f"{b_small.n_tasks:,}-task one ({b_large.durable.wall / b_small.durable.wall:.1f}× "
            "its wall time)."
        )
    return before_text


def report(after: list[SizeResult], before: list[SizeResult] | None) -> str:
    large = after[-1]
    headers = [
        "code",
        "tasks",
        "in memory: CPU (wall)",
        "durable, polled: CPU (wall)",
        "polls (their CPU, est.)",
        "durable / in-memory CPU",
        "same, polls left out",
        "load average (1 min)",
        "each pair in order: ms of CPU a task (in memory / durable)",
    ]
    rows = _rows("this branch", after)
    if before:
        rows = _rows("before", before) + rows
    verdicts = _verdicts(after)
    before_text = _before_text(before)
    order = ", ".join(f"{n:,}" for n in SCHEDULE)
    return (
        "A `rules` run of a synthetic instance (seed 0, 4 robots, `balanced`) at each size, in "
        "one server started by `scripts/serve.sh` per code version (uvicorn, SQLite, "
        "`LTAA_MAX_CONCURRENT_RUNS=1`): first `POST /allocate` with solver `ltaa` (the LTAA "
        "graph with InMemorySaver and the in-memory recorder, no database), then `POST "
        "/runs` (the real RunWorker: app tables through SQLAlchemy, the SQLite checkpointer, "
        "durability `sync`) with `GET /runs/{id}` every 0.5 s until it completes. CPU is the "
        "server process's (user + system, every thread, read from /proc) from the request "
        "to the answer, or to the poll that saw the run complete: **the polls run in the "
        "server and are counted** (the column beside says what the ratio is without them, "
        "each poll costed as one of the completed run, the dearest kind). Each size is "
        f"measured in pairs (in memory, then durable), in this order on one server: {order} "
        "tasks; each figure is the median of its kind (of an even count, the mean of the middle "
        "two). The small pairs bracket the large one, so a drift of the machine's "
        "speed during the measure moves both sides of the scaling ratio. Wall times are the "
        "client's; this 2-core machine is shared, so compare ratios within a row.\n\n"
        + table(headers, rows)
        + "\n\n"
        + verdicts
        + "\n\n"
        + growth(large)
        + "\n\n"
        + before_text
        + "\n\n"
        + _HISTORY
    )


def growth(large: SizeResult) -> str:
    """Whether a task costs more the longer the run: each durable run's CPU per task early
    and late in the run, read at its polls."""
    n = large.n_tasks

    def tasks(share: tuple[float, float]) -> str:
        return f"{share[0] * n:,.0f} to {share[1] * n:,.0f}"

    readings = []
    for d in large.durables:
        early, late = d.cpu_per_task(EARLY, n), d.cpu_per_task(LATE, n)
        readings.append(
            "too few polls to tell"
            if early is None or late is None
            else f"{fmt_time(early)} then {fmt_time(late)} (**{late / early:.2f}×**)"
        )
    return (
        f"**Does a task cost more the longer the run?** The server's CPU per task decided "
        f"(polls included) while a durable {n:,}-task run went from task {tasks(EARLY)}, then "
        f"from task {tasks(LATE)}, read from the server's CPU and the run's progress at each "
        f"poll: {'; '.join(readings)}."
    )


def run() -> Section:
    before_root = os.environ.get("LTAA_BENCH_BEFORE")
    before = measure(Path(before_root)) if before_root else None
    after = measure(ROOT)
    body = report(after, before) + f"\n_Measured on {dt.date.today().isoformat()}._\n"
    return Section("Durable runs: CPU against the same graph in memory", body)
