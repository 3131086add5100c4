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
from app.graph.recorder import AttemptRecord
from app.graph.runner import run_graph
from app.graph.state import ModelUse
from app.graph.usage import usage_from_attempts
from app.reasoners.attribution import REASONER, RULES
from app.reasoners.base import Reasoner, close_reasoner
from app.reasoners.factory import LLM_REASONERS, make_reasoner
from app.reasoners.scope import LLMScope
from app.solvers.ltaa import graph_context
from benchmarks.common import DOCS, machine, table
from benchmarks.llm_scope import MODES, PAPER_SECONDS_PER_TASK, PAPER_TOKENS_PER_TASK

REPORT = DOCS / "llm-benchmark.md"
QUALITY_THRESHOLD = 0.6
# How an unreadable reply's verdict begins (app.graph.reply_reading, app.graph.validation).
UNREADABLE = ("not complete JSON", "holds no JSON object", "no parseable decision")
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
    reply_format: str = "markdown"
    seconds: float = 0.0
    llm_tasks: int = 0  # tasks at which the model was asked at least once
    model_decided: int = 0  # decisions taken from the model's own answer
    unparseable: int = 0  # model replies with no readable answer (no JSON / cut JSON / no Decision)
    invalid_stored: int = 0  # stored decisions neither validated nor the fallback's (must be 0)
    gave_up_at: int | None = None  # the task from which the rule decided (give-up rule)
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
    model_use: ModelUse | None = None,
) -> LiveCell:
    problem = Problem.build(_instance(scenario_name, n_tasks), mode)
    recorder = MemoryRecorder()
    reasoner = make(scope)
    use = model_use or ModelUse()
    ctx = graph_context(
        problem,
        reasoner=reasoner,
        recorder=recorder,
        quality_threshold=QUALITY_THRESHOLD,
        max_retries=3,
        guidance="optimizer" if guided else None,
        model_use=use,
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
        reply_format=use.reply_format.value,
        seconds=time.perf_counter() - started,
    )
    _model_figures(cell, recorder)
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


def _model_figures(cell: LiveCell, recorder: MemoryRecorder) -> None:
    """What the model itself did: the decisions it made, its unreadable replies, the task
    the give-up rule fired at; and that every stored decision passed validation or is the
    fallback's (the graph's guarantee, counted here rather than assumed)."""
    by_task: dict[int, list[AttemptRecord]] = {}
    for a in recorder.attempts():
        by_task.setdefault(a.task_index, []).append(a)
    for d in recorder.decisions():
        attempts = by_task.get(d.task_index, [])
        accepted = [a for a in attempts if a.accepted]
        if not d.fallback and not (
            len(accepted) == 1
            and accepted[0].hard_invalid is None
            and (accepted[0].quality or 0.0) >= QUALITY_THRESHOLD
        ):
            cell.invalid_stored += 1
        if accepted and not d.fallback and _by_model(accepted[0]):
            cell.model_decided += 1
    for a in recorder.attempts():
        if _by_model(a) and a.reply is not None and a.reply.model is not None:
            why = a.hard_invalid or ""
            if any(mark in why for mark in UNREADABLE):
                cell.unparseable += 1
    if recorder.gave_up is not None:
        cell.gave_up_at = recorder.gave_up.task_index


def _by_model(attempt: AttemptRecord) -> bool:
    reply = attempt.reply
    return reply is not None and reply.extra.get(REASONER, RULES) != RULES


def run_cells(
    make: ReasonerFactory,
    *,
    scenario_names: Sequence[str] | None = None,
    modes: Sequence[Mode] = MODES,
    n_tasks: int | None = None,
    progress: Callable[[LiveCell], None] | None = None,
    variants: Sequence[tuple[LLMScope, bool]] = VARIANTS,
    model_use: ModelUse | None = None,
) -> list[LiveCell]:
    out = []
    for name in scenario_names or scenarios():
        for mode in modes:
            for scope, guided in variants:
                cell = live_cell(
                    make, name, mode, scope, guided=guided, n_tasks=n_tasks, model_use=model_use
                )
                if progress is not None:
                    progress(cell)
                out.append(cell)
    return out


def reasoner_factory(
    name: str, *, settings: Any, model: str | None = None, reply_format: str = "json_schema"
) -> ReasonerFactory:
    """The configured reasoner, built fresh per cell (raises DomainError when it cannot be)."""
    if name not in LLM_REASONERS:
        raise ValueError(f"bench-llm measures an LLM reasoner ({', '.join(LLM_REASONERS)})")

    def make(scope: LLMScope) -> Reasoner:
        return make_reasoner(
            name, settings=settings, model=model, llm_scope=scope.value, reply_format=reply_format
        )

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
        c.reply_format,
        f"{c.tokens / n:,.0f}",
        f"{c.seconds / n:.2f}",
        f"{_pct(c.llm_tasks, n)} ({c.llm_tasks}/{n})",
        _pct(c.first_try, c.llm_tasks),
        str(c.model_decided),
        tiers,
        str(c.fallbacks),
        str(c.unparseable),
        "-" if c.gave_up_at is None else str(c.gave_up_at),
        str(c.transport_retries),
        _regret(c.regret),
    ]


def _summary(cells: Sequence[LiveCell]) -> list[list[str]]:
    rows = []
    groups = dict.fromkeys((c.scope, c.guided, c.reply_format) for c in cells)
    for scope, guided, fmt in groups:
        picked = [c for c in cells if (c.scope, c.guided, c.reply_format) == (scope, guided, fmt)]
        tasks = sum(c.n_tasks for c in picked)
        rows.append(
            [
                scope,
                "yes" if guided else "no",
                fmt,
                f"{sum(c.tokens for c in picked) / tasks:,.0f}",
                f"{sum(c.seconds for c in picked) / tasks:.2f}",
                _pct(sum(c.llm_tasks for c in picked), tasks),
                str(sum(c.model_decided for c in picked)),
                str(sum(c.fallbacks for c in picked)),
                str(sum(c.unparseable for c in picked)),
                str(sum(c.invalid_stored for c in picked)),
                _regret(sum(c.regret for c in picked)),
            ]
        )
    return rows


PREAMBLE = f"""# LLM benchmark

Every cell is one run of the LTAA graph (as `POST /allocate` with solver `ltaa` runs it: \
validation, tiered retries, rules fallback, exact regret) with an LLM reasoner; `contested` \
asks the model only for contested decisions \
([reasoners.md](reasoners.md#llm_scope-ask-the-model-only-where-it-matters)), the rules \
reasoner answers the rest. *Format* is how the model was asked \
([reasoners.md](reasoners.md#structured-replies)): `json_schema` / `json_object` (a \
structured reply, read against the decision's schema) or `markdown` (the paper's sections). \
Tokens are the server's reported prompt + completion tokens, divided by all the tasks of \
the cell; seconds are wall time per task (model latency included); *accepted at first try* \
counts among the tasks that asked the model; *decided by the model* counts the decisions \
taken from the model's own answer (the rest are the rule's: a fallback, a clear-cut \
decision, or after the give-up rule, [reasoners.md](reasoners.md#bounded-cost)); \
*unreadable* counts model replies with no readable decision (no JSON object, JSON cut off, \
no **Decision** line); *invalid stored* counts stored decisions that neither passed \
validation nor are the fallback's (the graph's guarantee: always 0); regret is expected \
success given away against the exact optimum.

The paper (Claude, scope all, unguided): **{PAPER_TOKENS_PER_TASK:,} tokens** and \
**{PAPER_SECONDS_PER_TASK} s** per task.

Each section below is one `ltaa bench-llm` run, titled by what answered; a run rewrites its \
own section and leaves the others.
"""

CELL_HEADERS = [
    "scenario",
    "mode",
    "scope",
    "guided",
    "format",
    "tokens/task",
    "s/task",
    "tasks calling the model",
    "accepted at first try",
    "decided by the model",
    "retries at tier 1 / 2 / 3",
    "fallbacks",
    "unreadable",
    "gave up at task",
    "transport retries",
    "regret vs optimum",
]
SUMMARY_HEADERS = [
    "scope",
    "guided",
    "format",
    "tokens/task",
    "s/task",
    "tasks calling the model",
    "decided by the model",
    "fallbacks",
    "unreadable",
    "invalid stored",
    "total regret",
]


def render(
    cells: Sequence[LiveCell],
    *,
    title: str,
    reasoner: str,
    endpoint: str,
    model: str,
    label: str | None,
    settings: str,
) -> str:
    """One run's section: what produced it, its summary and every cell."""
    produced_by = label or f"the `{reasoner}` reasoner against {endpoint}"
    return (
        f"## {title}\n\n"
        f"**Produced by:** {produced_by}.  \n"
        f"**Reasoner:** `{reasoner}`, model `{model}`, endpoint `{endpoint}`; {settings}.  \n"
        f"**Generated:** {dt.date.today().isoformat()} by `ltaa bench-llm` ({machine()}).\n\n"
        "### Summary\n\n"
        + table(SUMMARY_HEADERS, _summary(cells))
        + "\n\n### Every cell\n\n"
        + table(CELL_HEADERS, [_row(c) for c in cells])
        + "\n"
    )


def write(section: str, path: Path = REPORT) -> Path:
    """`section` in the report at `path`: it replaces the section of the same title and
    keeps every other one (the preamble is rewritten)."""
    title = section.splitlines()[0]
    sections = [part for part in _sections(path) if part.splitlines()[0] != title]
    path.parent.mkdir(parents=True, exist_ok=True)
    body = "\n".join(s.rstrip() + "\n" for s in [*sections, section])
    path.write_text(PREAMBLE + "\n" + body, encoding="utf-8")
    return path


def _sections(path: Path) -> list[str]:
    """The report's run sections (each from its `## ` title), without the preamble."""
    if not path.exists():
        return []
    parts: list[str] = []
    for line in path.read_text(encoding="utf-8").splitlines(keepends=True):
        if line.startswith("## "):
            parts.append(line)
        elif parts:
            parts[-1] += line
    return parts
