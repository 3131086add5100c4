"""The LTAA graph's costs and decision quality (issue 3's figures, issue 4's regret table):
prompt size per task, durable-run wall time and checkpoint bytes, saver choice, and the
rules reasoner's gap to optimal with and without optimizer guidance.
"""

from __future__ import annotations

import dataclasses
import statistics
import tempfile
import time
import uuid
from functools import partial
from pathlib import Path
from typing import Any

from langgraph.checkpoint.base import BaseCheckpointSaver
from langgraph.checkpoint.memory import InMemorySaver

from app.domain.catalog import scenario, scenarios
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.graph.builder import build_graph
from app.graph.checkpoint import open_sqlite_saver
from app.graph.context import decision_context
from app.graph.memory_recorder import MemoryRecorder
from app.graph.prompts import SYSTEM_PROMPT, TARGET_USER_PROMPT_CHARS, prompt_size
from app.graph.runner import run_graph
from app.graph.state import initial_state, task_view
from app.reasoners.rules import RulesReasoner
from app.solvers.ltaa import graph_context
from benchmarks import plots
from benchmarks.cache import GUIDED, solved
from benchmarks.common import Section, fmt_time, median_seconds, synthetic_instance, table
from benchmarks.durable import DurableMeasure, measure_durable

PAPER_CHARS, PAPER_TOKENS = 5_724, 1_088
SMART_LLM_CHARS = 42_808
CHARS_PER_TOKEN = 4  # rough rule of thumb for English text; not a tokenizer count
SMALL_RUNS, SMALL_WARMUP = 5, 1
LARGE_TASKS, LARGE_ROBOTS, LARGE_RUNS = 1_000, 4, 2
TARGET_SMALL_S, TARGET_LARGE_S, TARGET_BYTES_PER_TASK = 0.5, 15.0, 20 * 1024
SAVER_REPEATS = 3


def baseline_problem(mode: Mode = Mode.BALANCED) -> Problem:
    return Problem.build(scenario("baseline").instance, mode)


def _run_in_memory(
    problem: Problem, guidance: str | None, *, regret: bool = True
) -> MemoryRecorder:
    recorder = MemoryRecorder()
    ctx = graph_context(
        problem,
        reasoner=RulesReasoner(),
        recorder=recorder,
        quality_threshold=0.6,
        max_retries=3,
        guidance=guidance,
    )
    if not regret:
        ctx = dataclasses.replace(ctx, regret=None)
    run_graph(build_graph(InMemorySaver()), ctx, uuid.uuid4().hex, resume=False)
    return recorder


def in_memory_seconds(problem: Problem, *, regret: bool) -> tuple[float, float]:
    """Wall and CPU seconds of one rules run with no database at all."""
    start, cpu = time.perf_counter(), time.process_time()
    _run_in_memory(problem, None, regret=regret)
    return time.perf_counter() - start, time.process_time() - cpu


def sent_prompt_chars(problem: Problem, guidance: str | None = None) -> list[int]:
    """System + user characters of every prompt a rules run actually recorded."""
    return [
        len(a.system_prompt) + len(a.user_prompt)
        for a in _run_in_memory(problem, guidance).attempts()
    ]


def retry_tier_chars(problem: Problem) -> dict[int, list[int]]:
    """System + user characters per retry tier, rebuilt at every decision of a rules run
    (the rules reasoner never needs a retry, so these prompts are never sent by it)."""
    sizes: dict[int, list[int]] = {tier: [] for tier in (1, 2, 3)}
    state: dict[str, Any] = initial_state(problem)
    for d in _run_in_memory(problem, None).decisions():
        state = {
            **state,
            "task_index": d.task_index,
            "loads": d.loads_before,
            "view": task_view(problem, d.task_index, d.loads_before, None),
        }
        dctx = decision_context(problem, state)
        for tier in sizes:
            sizes[tier].append(prompt_size(dctx, tier)["total_chars"])
    return sizes


def _tokens(chars: float) -> str:
    return f"~{chars / CHARS_PER_TOKEN:,.0f}"


def prompt_part(problem: Problem) -> tuple[str, list[tuple[str, float]]]:
    rows: list[list[Any]] = []
    bars: list[tuple[str, float]] = []
    unguided = sent_prompt_chars(problem)
    for label, chars in (
        ("tier 0, unguided (what a first attempt sends)", unguided),
        ("tier 0, optimizer-guided", sent_prompt_chars(problem, "optimizer")),
    ):
        mean = statistics.fmean(chars)
        rows.append([label, f"{min(chars):,}", f"{mean:,.0f}", f"{max(chars):,}", _tokens(mean)])
        bars.append((f"ours: {label.split(' (')[0]}", mean))
    for tier, chars in retry_tier_chars(problem).items():
        mean = statistics.fmean(chars)
        rows.append(
            [
                f"tier {tier} retry (feedback text excluded)",
                f"{min(chars):,}",
                f"{mean:,.0f}",
                f"{max(chars):,}",
                _tokens(mean),
            ]
        )
        if tier == 2:
            bars.append(("ours: tier 2 retry (the largest)", mean))
    rows.append(
        [
            "paper's LTAA prompt, per task",
            "-",
            f"{PAPER_CHARS:,}",
            "-",
            f"{PAPER_TOKENS:,} (reported)",
        ]
    )
    rows.append(
        [
            "SMART-LLM concatenated examples",
            "-",
            f"{SMART_LLM_CHARS:,}",
            "-",
            _tokens(SMART_LLM_CHARS),
        ]
    )
    bars += [("paper's LTAA (reported)", PAPER_CHARS), ("SMART-LLM examples", SMART_LLM_CHARS)]
    text = table(["prompt", "min chars", "mean chars", "max chars", "tokens per task"], rows)
    user = statistics.fmean(unguided) - len(SYSTEM_PROMPT)
    text += (
        f"\n\nIssue 3's target for the dynamic user prompt alone: ≤ "
        f"{TARGET_USER_PROMPT_CHARS:,} characters; measured {user:,.0f} on average at "
        f"tier 0 — {_verdict(user <= TARGET_USER_PROMPT_CHARS)}."
    )
    return text, bars


def saver_rows(problem: Problem, workdir: Path) -> list[list[Any]]:
    """The graph alone (in-memory recorder) over each saver, to show what persistence costs."""

    def one_run(saver: BaseCheckpointSaver[Any]) -> None:
        ctx = graph_context(
            problem,
            reasoner=RulesReasoner(),
            recorder=MemoryRecorder(),
            quality_threshold=0.6,
            max_retries=3,
            guidance=None,
        )
        run_graph(build_graph(saver), ctx, uuid.uuid4().hex, resume=False)

    memory = InMemorySaver()
    rows: list[list[Any]] = [
        [
            "InMemorySaver",
            "-",
            fmt_time(median_seconds(lambda: one_run(memory), SAVER_REPEATS)),
            "-",
        ]
    ]
    for compact in (False, True):
        for sync in (None, "NORMAL"):
            path = workdir / f"cp-{compact}-{sync}.sqlite"
            saver = open_sqlite_saver(path, compact=compact, synchronous=sync)
            seconds = median_seconds(partial(one_run, saver), SAVER_REPEATS)
            saver.conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            per_task = path.stat().st_size / (SAVER_REPEATS + 1) / problem.instance.n_tasks
            rows.append(
                [
                    "CompactSqliteSaver" if compact else "SqliteSaver",
                    sync or "FULL (setup default)",
                    fmt_time(seconds),
                    f"{per_task / 1024:.1f} KB",
                ]
            )
            saver.conn.close()
    return rows


def _verdict(ok: bool) -> str:
    return "met" if ok else "**missed**"


def _durable_rows(small: DurableMeasure, large: DurableMeasure) -> list[list[str]]:
    """The wall-time and checkpoint-size targets, with their verdicts."""
    rows: list[list[str]] = []
    for m, target in ((small, TARGET_SMALL_S), (large, TARGET_LARGE_S)):
        med = statistics.median(m.seconds)
        runs = ", ".join(
            f"{fmt_time(w)} (CPU {fmt_time(c)})"
            for w, c in zip(m.seconds, m.cpu_seconds, strict=True)
        )
        rows.append(
            [
                f"wall time, {m.n_tasks:,} tasks",
                f"{fmt_time(med)} (median of {len(m.seconds)}; runs: {runs})",
                f"≤ {target:g} s",
                _verdict(med <= target),
            ]
        )
    for m in (small, large):
        rows.append(
            [
                f"checkpoint bytes per task, {m.n_tasks:,} tasks",
                f"{m.per_task / 1024:.1f} KB ({m.checkpoint_after_wal_checkpoint:,} B "
                "after a WAL checkpoint)",
                f"≤ {TARGET_BYTES_PER_TASK // 1024} KB",
                _verdict(m.per_task <= TARGET_BYTES_PER_TASK),
            ]
        )
    return rows


def _sizes_table(small: DurableMeasure, large: DurableMeasure) -> str:
    return table(
        [
            "tasks",
            "checkpoint file as left",
            "its -wal as left",
            "file after WAL checkpoint",
            "per task",
            "app tables (ltaa.db + -wal)",
        ],
        [
            [
                f"{m.n_tasks:,}",
                f"{m.checkpoint_main_bytes:,} B",
                f"{m.checkpoint_wal_bytes:,} B",
                f"{m.checkpoint_after_wal_checkpoint:,} B",
                f"{m.per_task / 1024:.1f} KB",
                f"{m.app_db_bytes:,} B",
            ]
            for m in (small, large)
        ],
    )


def durable_part(
    small: DurableMeasure,
    large: DurableMeasure,
    in_memory: tuple[tuple[float, float], tuple[float, float]],
) -> str:
    rows = _durable_rows(small, large)
    sizes = _sizes_table(small, large)
    warm = ", ".join(fmt_time(x) for x in small.warmup_seconds)
    l_med, l_cpu = statistics.median(large.seconds), statistics.median(large.cpu_seconds)
    with_regret, no_regret = in_memory
    return (
        "A durable `rules` run as the server executes it: `service.create_run` + the real "
        "`RunWorker` (app tables through SQLAlchemy in `ltaa.db`, WAL, synchronous=NORMAL; "
        "the compact SQLite checkpointer, durability `sync`, synchronous=NORMAL), timed from "
        "`create_run` to the run's completion; CPU is this process's CPU time (all threads) "
        "over the same span, so wall time far above it means the run waited for a CPU held "
        "by other processes on this shared machine. "
        f"{small.n_tasks} tasks: baseline scenario, `balanced`; {len(small.warmup_seconds)} "
        f"warm-up run(s) ({warm}) then {len(small.seconds)} timed runs, median. "
        f"{large.n_tasks:,} tasks: synthetic instance (seed 0, {LARGE_ROBOTS} robots, "
        f"3 features), `balanced`; {len(large.seconds)} timed run(s), median. Checkpoint "
        "bytes: the first run in a fresh data directory, the file measured after "
        "`PRAGMA wal_checkpoint(TRUNCATE)` (the -wal file folded in; summing the file and "
        "-wal as the run left them would count pages twice). The saver prunes a run's "
        "superseded checkpoints as it goes (see the bounded-storage section) and the worker "
        "deletes the rest once it completes; SQLite keeps the freed pages for the next run, "
        "so the file's size is the run's high-water mark.\n\n"
        + table(["measure", "measured", "target", "verdict"], rows)
        + "\n\n"
        + sizes
        + "\n\n"
        f"Where the {large.n_tasks:,}-task time goes (same instance; the in-memory rows are "
        "one run each; differences taken on CPU time, which other processes disturb less "
        "than wall time):\n\n"
        + table(
            ["run", "wall time", "CPU time", "difference (CPU)"],
            [
                [
                    "durable (above, median)",
                    fmt_time(l_med),
                    fmt_time(l_cpu),
                    f"persistence: {fmt_time(l_cpu - with_regret[1])}",
                ],
                [
                    "in memory (InMemorySaver, in-memory recorder, no database)",
                    fmt_time(with_regret[0]),
                    fmt_time(with_regret[1]),
                    f"exact per-decision regret: {fmt_time(with_regret[1] - no_regret[1])}",
                ],
                [
                    "in memory, regret switched off",
                    fmt_time(no_regret[0]),
                    fmt_time(no_regret[1]),
                    "the rest: LangGraph's 7 super-steps per task, rules reasoner, prompt, "
                    "validation",
                ],
            ],
        )
        + "\n\nPersistence is the checkpoint rows written at every super-step plus one upsert "
        "per attempt and decision in the app tables (with the decision's hash-chain link); "
        "the regret is one min-cost flow over the remaining tasks per decision, so it grows "
        "with the queue length.\n\n"
        f"The wall-time targets are absolute, the machine is not: the durable run costs "
        f"{l_cpu / with_regret[1]:.2f}× the in-memory run's CPU time (a ratio that moves "
        f"little between machines), and the {large.n_tasks:,}-task target holds here with a "
        f"margin of {TARGET_LARGE_S / l_med:.2f}× (the 36-task one with "
        f"{TARGET_SMALL_S / statistics.median(small.seconds):.2f}×): a machine that much "
        "slower per core would miss them. An earlier generation of this report, on a slower "
        "machine (same code before issue 6, in-memory run 10.85 s CPU), measured 20.35 s and "
        "0.65 s.\n"
    )


def _points(x: float) -> str:
    # Float noise must not print as "-0.00".
    return f"{abs(x) * 100 if abs(x) < 5e-5 else x * 100:.2f}"


def regret_part() -> str:
    rows = []
    worst_identity = worst_guided = 0.0
    for sc in scenarios():
        for mode in Mode:
            opt = solved("optimal", sc, mode.value).metrics.expected_success
            un = solved("ltaa", sc, mode.value)
            gd = solved("ltaa", sc, mode.value, options=GUIDED)
            gap = opt - un.metrics.expected_success
            regret = float(un.details["regret"])
            worst_identity = max(worst_identity, abs(gap - regret))
            worst_guided = max(
                worst_guided,
                abs(float(gd.details["regret"])),
                abs(opt - gd.metrics.expected_success),
            )
            rows.append(
                [
                    sc,
                    mode.value,
                    "none" if un.max_deviation is None else f"{un.max_deviation:g}",
                    f"{opt * 100:.2f}%",
                    f"{un.metrics.expected_success * 100:.2f}%",
                    _points(gap),
                    _points(regret),
                    f"{gd.metrics.expected_success * 100:.2f}%",
                    f"{float(gd.details['regret']) * 100:.1e}",
                ]
            )
    return (
        "The `ltaa` solver (rules reasoner, default options; the same graph as a durable run, "
        "in memory), every scenario × mode with the mode's default cap, seed 0 (the rules "
        "reasoner is deterministic). Regret is summed over the run's per-decision regrets "
        "(stored in each decision record), in percentage points of expected success.\n\n"
        + table(
            [
                "scenario",
                "mode",
                "cap",
                "optimal",
                "LTAA unguided",
                "gap (points)",
                "Σ regret (points)",
                "LTAA guided",
                "guided Σ regret (points)",
            ],
            rows,
        )
        + f"\n\nLargest |gap − Σ regret| over the 12 unguided runs: {worst_identity:.1e} "
        f"(regrets telescope to the gap). Guided: largest |regret| or gap to optimal "
        f"{worst_guided:.1e} — {_verdict(worst_guided <= 1e-9)} against the target of 0 "
        "(to 1e-9) on all 12. The unguided gap is the paper's decision rule at work, not a "
        "defect: the trade-off rule looks one task ahead, the optimum looks at the whole "
        "queue.\n"
    )


def run() -> Section:
    problem = baseline_problem()
    prompt_table, bars = prompt_part(problem)
    image = plots.hbar_figure(
        bars,
        "characters per task (system + user prompt)",
        "Prompt size per task: LTAA here vs the paper and SMART-LLM",
        "Ours: mean over the 36 decisions of a rules run on baseline/balanced (exact "
        "character counts). Paper: 5,724 characters per task as reported; SMART-LLM: 42,808 "
        "characters of concatenated examples.",
        "prompt_size.png",
    )
    small = measure_durable(problem.instance, runs=SMALL_RUNS, warmup=SMALL_WARMUP)
    large_instance = synthetic_instance(LARGE_TASKS, LARGE_ROBOTS, seed=0)
    large = measure_durable(large_instance, runs=LARGE_RUNS)
    large_problem = Problem.build(large_instance, Mode.BALANCED)
    in_memory = (
        in_memory_seconds(large_problem, regret=True),
        in_memory_seconds(large_problem, regret=False),
    )
    with tempfile.TemporaryDirectory() as tmp:
        savers = saver_rows(problem, Path(tmp))
    body = (
        "### Prompt size per task\n\n"
        f"Baseline scenario, `balanced`, 36 decisions of a rules run. Characters are exact "
        f"(system prompt {len(SYSTEM_PROMPT)} characters + the user prompt); tokens are an "
        f"**estimate** at {CHARS_PER_TOKEN} characters per token, not a tokenizer count (the "
        f"paper's own ratio is {PAPER_CHARS / PAPER_TOKENS:.1f}). The prompt grows with the "
        "number of robots, not with the queue length.\n\n"
        f"{prompt_table}\n\n![Prompt size per task]({image})\n\n"
        "### Durable runs: wall time and checkpoint size\n\n"
        + durable_part(small, large, in_memory)
        + "\n### Checkpointer choice\n\n"
        f"The graph alone (in-memory recorder, no app tables) on baseline/`balanced`, 36 tasks, "
        f"median of {SAVER_REPEATS} runs after a warm-up; file bytes per task after a WAL "
        "checkpoint. With SQLite's FULL synchronous every super-step pays two fsyncs "
        "(put, put_writes); NORMAL in WAL mode still survives kill -9 (committed pages are "
        "in the OS cache) and may lose the last steps only on power loss. The worker uses "
        "CompactSqliteSaver + NORMAL.\n\n"
        + table(["saver", "PRAGMA synchronous", "wall time", "file per task"], savers)
        + "\n\n### Rules reasoner vs optimal: per-run regret\n\n"
        + regret_part()
    )
    return Section("LTAA runs: prompt size, durable runs, regret", body, [image])
