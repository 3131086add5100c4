"""llm_scope 'contested' offline (issue 15): how many decisions would ask the LLM, and
what that saves, computed exactly from the graph with counting fake reasoners.

No model is called. Each of the 12 scenario x mode cells runs the LTAA graph (in memory,
with exact regret) with the ContestedOnlyReasoner around a fake that counts its calls;
the share of tasks that called it is exact. Tokens are an estimate: each call is priced at
the paper's measured 1,088 tokens per task (prompt + answer), the only per-call figure
measured against a real model; first tries only (a real model's retries add to both
scopes alike).

Two fakes, for the acceptance checks:
- RulesEquivalent answers what the rules reasoner would; under it 'contested' must give
  the same allocation as 'all' (the clear-cut answers are the same answers).
- GuidanceFollower always takes the optimizer's guided robot; under it 'contested' with
  guidance must keep regret 0 (clear-cut decisions are the ones the rule and the
  optimizer agree on, and the rules reasoner follows guidance too).
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass

from langgraph.checkpoint.memory import InMemorySaver

from app.domain.catalog import scenario, scenarios
from app.domain.decision import DecisionContext
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.graph.builder import build_graph
from app.graph.memory_recorder import MemoryRecorder
from app.graph.runner import run_graph
from app.reasoners.base import Reasoner, ReasonerReply
from app.reasoners.rules import choose, compose_answer
from app.reasoners.scope import DEFAULT_LLM_MARGIN, LLMScope, scoped
from app.reasoners.structured import ReplySchema
from app.solvers.ltaa import graph_context
from benchmarks.common import Section, table

PAPER_TOKENS_PER_TASK = 1_088  # the paper's measured prompt + answer tokens per decision
PAPER_SECONDS_PER_TASK = 4.14
TARGET_SHARE = 0.40  # issue 15: at most 40% of decisions on baseline / balanced
MODES = (Mode.SUCCESS_FOCUSED, Mode.BALANCED, Mode.AGGRESSIVE_BALANCE)


@dataclass
class CountingReasoner:
    """A fake LLM: answers in the required format, names a model (so its replies count as
    LLM calls, as the trace and usage count them) and counts the decisions it was asked."""

    name: str = "counting"
    calls: int = 0
    tasks: set[int] | None = None

    def answer(self, ctx: DecisionContext) -> str:
        return compose_answer(ctx)

    def reason(
        self,
        system: str,
        user: str,
        context: DecisionContext,
        schema: ReplySchema | None = None,
    ) -> ReasonerReply:
        self.calls += 1
        if self.tasks is None:
            self.tasks = set()
        self.tasks.add(context.task_index)
        return ReasonerReply(text=self.answer(context), model=self.name)


class RulesEquivalent(CountingReasoner):
    """Answers exactly what the rules reasoner would."""


class GuidanceFollower(CountingReasoner):
    """Always names the optimizer's guided robot (it needs guidance on)."""

    def answer(self, ctx: DecisionContext) -> str:
        if ctx.guided_robot is None or ctx.guided_robot not in ctx.feasible:
            raise ValueError("GuidanceFollower needs optimizer guidance the cap allows")
        # The rules reasoner's answer with guidance on names the guided robot and says the
        # choice follows the guidance (against the rule, where they differ).
        assert choose(ctx)[0] == ctx.guided_robot
        return compose_answer(ctx)


@dataclass(frozen=True)
class ScopeRun:
    scenario: str
    mode: str
    scope: str
    guided: bool
    n_tasks: int
    llm_tasks: int  # tasks at which the fake was called at least once
    llm_calls: int
    assignment: tuple[int, ...]
    regret: float

    @property
    def share(self) -> float:
        return self.llm_tasks / self.n_tasks

    @property
    def est_tokens(self) -> int:
        return self.llm_calls * PAPER_TOKENS_PER_TASK


def scope_run(
    scenario_name: str,
    mode: Mode,
    scope: LLMScope,
    *,
    guided: bool = False,
    fake: CountingReasoner | None = None,
    margin: float = DEFAULT_LLM_MARGIN,
) -> ScopeRun:
    problem = Problem.build(scenario(scenario_name).instance, mode)
    llm = fake if fake is not None else RulesEquivalent()
    reasoner: Reasoner = scoped(llm, scope.value, margin)
    recorder = MemoryRecorder()
    ctx = graph_context(
        problem,
        reasoner=reasoner,
        recorder=recorder,
        quality_threshold=0.6,
        max_retries=3,
        guidance="optimizer" if guided else None,
    )
    run_graph(build_graph(InMemorySaver()), ctx, uuid.uuid4().hex, resume=False)
    decisions = recorder.decisions()
    return ScopeRun(
        scenario=scenario_name,
        mode=mode.value,
        scope=scope.value,
        guided=guided,
        n_tasks=problem.instance.n_tasks,
        llm_tasks=len(llm.tasks or ()),
        llm_calls=llm.calls,
        assignment=tuple(d.robot for d in decisions),
        regret=sum(d.regret or 0.0 for d in decisions),
    )


def cells() -> list[tuple[str, Mode]]:
    return [(name, mode) for name in scenarios() for mode in MODES]


def _pct(x: float) -> str:
    return f"{x * 100:.0f}%"


def _regret(x: float) -> str:
    return f"{abs(x) if abs(x) < 5e-5 else x:.4f}"  # no "-0.0000" from float sums


def run() -> Section:
    rows = []
    baseline_share = 0.0
    shares: list[float] = []
    for name, mode in cells():
        everything = scope_run(name, mode, LLMScope.ALL)
        unguided = scope_run(name, mode, LLMScope.CONTESTED)
        guided = scope_run(name, mode, LLMScope.CONTESTED, guided=True, fake=GuidanceFollower())
        if (name, mode) == ("baseline", Mode.BALANCED):
            baseline_share = unguided.share
        shares.append(unguided.share)
        n = unguided.n_tasks
        rows.append(
            [
                name,
                mode.value,
                f"{_pct(unguided.share)} ({unguided.llm_tasks}/{n})",
                f"{_pct(guided.share)} ({guided.llm_tasks}/{n})",
                f"{unguided.est_tokens / n:,.0f} / {guided.est_tokens / n:,.0f}",
                f"{unguided.est_tokens:,} / {guided.est_tokens:,}",
                f"{everything.est_tokens:,}",
                "yes" if unguided.assignment == everything.assignment else "**no**",
                _regret(guided.regret),
            ]
        )
    verdict = "met" if baseline_share <= TARGET_SHARE else "**not met**"
    body = (
        'Share of decisions that ask the LLM under `llm_scope: "contested"` (default margin '
        f"{DEFAULT_LLM_MARGIN:g} points), on every scenario x mode cell. Exact: the LTAA graph "
        "run in memory with a counting fake LLM behind the contested-only wrapper. Tokens "
        f"are an **estimate**: every call priced at the paper's {PAPER_TOKENS_PER_TASK:,} "
        "tokens per task (its measured prompt + answer), first tries only; `all` asks the "
        f"model at every decision, {PAPER_TOKENS_PER_TASK:,} tokens per task. At the paper's "
        f"{PAPER_SECONDS_PER_TASK} s per call, the time saved is in the same proportion.\n\n"
        + table(
            [
                "scenario",
                "mode",
                "LLM share, unguided",
                "LLM share, guided",
                "est. tokens/task, contested: unguided / guided",
                "est. tokens/run, contested: unguided / guided",
                "est. tokens/run, all",
                "same allocation as all (rules-equivalent fake)",
                "regret, contested + guidance (guidance-following fake)",
            ],
            rows,
        )
        + f"\n\nBaseline / `balanced`: {_pct(baseline_share)} of the decisions ask the model "
        f"(target at most {_pct(TARGET_SHARE)}: {verdict}); over the 12 cells "
        f"{_pct(min(shares))} to {_pct(max(shares))}. With guidance a decision is also "
        "contested where the optimizer names another robot than the rule, so the guided "
        "share is the higher one. Live figures with a real model: `make bench-llm` "
        "(docs/llm-benchmark.md).\n"
    )
    return Section("LLM scope: contested decisions only (offline)", body)
