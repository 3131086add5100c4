"""`ltaa bench-llm`: the LTAA graph with the configured LLM reasoner on the 4 scenarios x 3
modes, scope 'all' and 'contested', guided and unguided, written to docs/llm-benchmark.md
beside the paper's measured 1,088 tokens and 4.14 s per task.

For an operator with an API key or a local OpenAI-compatible server: every figure comes
from a real run of the graph (in memory, as POST /allocate runs it) against whatever the
server's settings point at, and the report says which server that was. Nothing here is
estimated: tokens are what the server reported, seconds are wall time per task.
"""

from __future__ import annotations

import datetime as dt
import time
import uuid
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from langgraph.checkpoint.memory import InMemorySaver

from app.domain.catalog import scenario, scenarios
from app.domain.models import Instance
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.graph.builder import build_graph
from app.graph.memory_recorder import MemoryRecorder
from app.graph.runner import run_graph
from app.graph.usage import usage_from_attempts
from app.reasoners.attribution import REASONER, RULES
from app.reasoners.base import Reasoner, close_reasoner
from app.reasoners.factory import LLM_REASONERS, make_reasoner
from app.reasoners.scope import LLMScope
from app.solvers.ltaa import graph_context
from benchmarks.common import DOCS, machine, table
from benchmarks.llm_scope import MODES, PAPER_SECONDS_PER_TASK, PAPER_TOKENS_PER_TASK

REPORT = DOCS / "llm-benchmark.md"
VARIANTS = (
    (LLMScope.ALL, False),
    (LLMScope.ALL, True),
    (LLMScope.CONTESTED, False),
    (LLMScope.CONTESTED, True),
)
ReasonerFactory = Callable[[LLMScope], Reasoner]


@dataclass
class LiveCell:
    scenario: str
    mode: str
    scope: str
    guided: bool
    n_tasks: int
    seconds: float = 0.0
    llm_tasks: int = 0  # tasks at which the model was asked at least once
    input_tokens: int = 0
    output_tokens: int = 0
    first_try: int = 0  # of the llm_tasks: accepted at attempt 1
    retries_by_tier: Counter[int] = field(default_factory=Counter)
    fallbacks: int = 0
    transport_retries: int = 0
    regret: float = 0.0

    @property
    def tokens(self) -> int:
        return self.input_tokens + self.output_tokens


def _instance(name: str, n_tasks: int | None) -> Instance:
    inst = scenario(name).instance
    if n_tasks is None or n_tasks >= inst.n_tasks:
        return inst
    return Instance(tasks=inst.tasks[:n_tasks], robots=inst.robots)


def live_cell(
    make: ReasonerFactory,
    scenario_name: str,
    mode: Mode,
    scope: LLMScope,
    *,
    guided: bool,
    n_tasks: int | None = None,
) -> LiveCell:
    problem = Problem.build(_instance(scenario_name, n_tasks), mode)
    recorder = MemoryRecorder()
    reasoner = make(scope)
    ctx = graph_context(
        problem,
        reasoner=reasoner,
        recorder=recorder,
        quality_threshold=0.6,
        max_retries=3,
        guidance="optimizer" if guided else None,
    )
    started = time.perf_counter()
    try:
        run_graph(build_graph(InMemorySaver()), ctx, uuid.uuid4().hex, resume=False)
    finally:
        close_reasoner(reasoner)
    cell = LiveCell(
        scenario_name,
        mode.value,
        scope.value,
        guided,
        problem.instance.n_tasks,
        seconds=time.perf_counter() - started,
    )
    attempts = recorder.attempts()
    usage = usage_from_attempts(attempts)
    cell.input_tokens, cell.output_tokens = usage.input_tokens, usage.output_tokens
    cell.transport_retries = usage.transport_retries
    asked = {
        a.task_index
        for a in attempts
        if a.reply is not None and a.reply.extra.get(REASONER, RULES) != RULES
    }
    cell.llm_tasks = len(asked)
    for a in attempts:
        if a.task_index in asked and a.tier > 0:
            cell.retries_by_tier[a.tier] += 1
    for d in recorder.decisions():
        cell.fallbacks += d.fallback
        cell.regret += d.regret or 0.0
        if d.task_index in asked and d.attempts == 1 and not d.fallback:
            cell.first_try += 1
    return cell


def run_cells(
    make: ReasonerFactory,
    *,
    scenario_names: Sequence[str] | None = None,
    modes: Sequence[Mode] = MODES,
    n_tasks: int | None = None,
    progress: Callable[[LiveCell], None] | None = None,
) -> list[LiveCell]:
    out = []
    for name in scenario_names or scenarios():
        for mode in modes:
            for scope, guided in VARIANTS:
                cell = live_cell(make, name, mode, scope, guided=guided, n_tasks=n_tasks)
                if progress is not None:
                    progress(cell)
                out.append(cell)
    return out


def reasoner_factory(name: str, *, settings: Any, model: str | None = None) -> ReasonerFactory:
    """The configured reasoner, built fresh per cell (raises DomainError when it cannot be)."""
    if name not in LLM_REASONERS:
        raise ValueError(f"bench-llm measures an LLM reasoner ({', '.join(LLM_REASONERS)})")

    def make(scope: LLMScope) -> Reasoner:
        return make_reasoner(name, settings=settings, model=model, llm_scope=scope.value)

    # Built once now, so a missing setting fails before any cell runs.
    close_reasoner(make(LLMScope.ALL))
    return make


def server_of(name: str, settings: Any, model: str | None) -> tuple[str, str]:
    """(endpoint, model) the reasoner called, for the report's first line."""
    if name == "openai":
        return str(settings.openai_base_url), str(model or settings.openai_model)
    url = settings.anthropic_base_url or "https://api.anthropic.com (the SDK's default)"
    return str(url), str(model or settings.default_model)


def _regret(x: float) -> str:
    return f"{abs(x) if abs(x) < 5e-5 else x:.4f}"  # no "-0.0000" from float sums


def _pct(part: int, whole: int) -> str:
    return f"{100 * part / whole:.0f}%" if whole else "-"


def _row(c: LiveCell) -> list[str]:
    n = c.n_tasks
    tiers = " / ".join(str(c.retries_by_tier.get(t, 0)) for t in (1, 2, 3))
    return [
        c.scenario,
        c.mode,
        c.scope,
        "yes" if c.guided else "no",
        f"{c.tokens / n:,.0f}",
        f"{c.seconds / n:.2f}",
        f"{_pct(c.llm_tasks, n)} ({c.llm_tasks}/{n})",
        _pct(c.first_try, c.llm_tasks),
        tiers,
        str(c.fallbacks),
        str(c.transport_retries),
        _regret(c.regret),
    ]


def _summary(cells: Sequence[LiveCell]) -> list[list[str]]:
    rows = []
    for scope, guided in VARIANTS:
        picked = [c for c in cells if c.scope == scope.value and c.guided == guided]
        tasks = sum(c.n_tasks for c in picked)
        if not tasks:
            continue
        rows.append(
            [
                scope.value,
                "yes" if guided else "no",
                f"{sum(c.tokens for c in picked) / tasks:,.0f}",
                f"{sum(c.seconds for c in picked) / tasks:.2f}",
                _pct(sum(c.llm_tasks for c in picked), tasks),
                str(sum(c.fallbacks for c in picked)),
                _regret(sum(c.regret for c in picked)),
            ]
        )
    return rows


def render(
    cells: Sequence[LiveCell], *, reasoner: str, endpoint: str, model: str, label: str | None
) -> str:
    produced_by = label or f"the `{reasoner}` reasoner against {endpoint}"
    headers = [
        "scenario",
        "mode",
        "scope",
        "guided",
        "tokens/task",
        "s/task",
        "tasks calling the model",
        "accepted at first try",
        "retries at tier 1 / 2 / 3",
        "fallbacks",
        "transport retries",
        "regret vs optimum",
    ]
    return (
        "# LLM benchmark\n\n"
        f"**Produced by:** {produced_by}.  \n"
        f"**Reasoner:** `{reasoner}`, model `{model}`, endpoint `{endpoint}`.  \n"
        f"**Generated:** {dt.date.today().isoformat()} by `ltaa bench-llm` ({machine()}).\n\n"
        "Every cell is one run of the LTAA graph (as `POST /allocate` with solver `ltaa` runs "
        "it: validation, tiered retries, rules fallback, exact regret) with the configured "
        "reasoner; `contested` asks the model only for contested decisions "
        "([reasoners.md](reasoners.md#llm_scope-ask-the-model-only-where-it-matters)), the "
        "rules reasoner answers the rest. Tokens are the server's reported prompt + "
        "completion tokens, divided by all the tasks of the cell; seconds are wall time per "
        "task (model latency included); *accepted at first try* counts among the tasks that "
        "asked the model; regret is expected success given away against the exact optimum.\n\n"
        f"The paper (Claude, scope all, unguided): **{PAPER_TOKENS_PER_TASK:,} tokens** and "
        f"**{PAPER_SECONDS_PER_TASK} s** per task.\n\n"
        "## Summary\n\n"
        + table(
            [
                "scope",
                "guided",
                "tokens/task",
                "s/task",
                "tasks calling the model",
                "fallbacks",
                "total regret",
            ],
            _summary(cells),
        )
        + f"\n| paper | no | {PAPER_TOKENS_PER_TASK:,} | {PAPER_SECONDS_PER_TASK} | 100% | - | - |"
        "\n\n## Every cell\n\n" + table(headers, [_row(c) for c in cells]) + "\n"
    )


def write(text: str, path: Path = REPORT) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path
