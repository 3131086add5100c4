"""The `ltaa` entry of POST /allocate: the LTAA graph run synchronously, in memory.

No durable run record: an InMemorySaver and the in-memory recorder live for one solve.
Durable, resumable runs are POST /runs (app.runs).
"""

from __future__ import annotations

import statistics
import uuid
from collections.abc import Mapping, Sequence
from typing import Any, Literal

from langgraph.checkpoint.memory import InMemorySaver
from langgraph.graph.state import CompiledStateGraph
from pydantic import Field

from app.domain.errors import DomainError
from app.domain.problem import Problem
from app.domain.review import Resolution, ReviewPolicy
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.progress import TimedProgress
from app.domain.scheduling.schedule import build_schedule
from app.graph.builder import build_graph
from app.graph.execution import Execution, execute
from app.graph.memory_recorder import MemoryRecorder
from app.graph.recorder import DecisionRecord, Recorder
from app.graph.review import ReviewGate
from app.graph.state import DEFAULT_MAX_RETRIES, GraphContext, Guidance, ModelUse, Regret
from app.graph.timing import decision_teams
from app.graph.validation import DEFAULT_QUALITY_THRESHOLD
from app.reasoners.base import Reasoner
from app.reasoners.factory import LLM_REASONERS, make_reasoner
from app.reasoners.scope import DEFAULT_LLM_MARGIN
from app.reasoners.structured import ReplyFormat
from app.solvers.base import Solution, Solver, SolverInfo, SolverOptions
from app.solvers.oracle import CompletionOracle
from app.solvers.timed_guidance import (
    GuidancePlan,
    ScheduleGuidance,
    guided_problem,
    plan_guidance,
)
from app.solvers.unit_oracle import UnitOracle


class LTAAOptions(SolverOptions):
    reasoner: str = "rules"
    quality_threshold: float = Field(DEFAULT_QUALITY_THRESHOLD, ge=0.0, le=1.0)
    max_retries: int = Field(DEFAULT_MAX_RETRIES, ge=0, le=10)
    model: str | None = None
    temperature: float | None = Field(None, ge=0.0, le=1.0)
    timeout: float | None = Field(None, gt=0.0)
    guidance: Literal["optimizer"] | None = None
    # docs/reasoners.md#llm_scope-ask-the-model-only-where-it-matters: 'contested' asks the LLM only
    # where the trade-off verdict is close to its threshold (within llm_margin points) or guidance
    # disagrees with the rule.
    llm_scope: Literal["all", "contested"] = "all"
    llm_margin: float = Field(DEFAULT_LLM_MARGIN, ge=0.0, le=100.0)
    # docs/reasoners.md#structured-replies: how the model is asked; None: the server's
    # LTAA_LLM_REPLY_FORMAT.
    reply_format: Literal["json_schema", "json_object", "markdown"] | None = None
    # No api_key / base_url here: a request must not choose where the server sends its
    # key (SSRF) nor carry secrets into logs; both come from the server's settings.


def model_use_for(reasoner: str, reply_format: str, give_up_after: int) -> ModelUse:
    """How a run asks its model: in `reply_format`, given up after `give_up_after` failed
    tasks in a row; a reasoner that calls no model (rules, replay) is never given up."""
    return ModelUse(
        reply_format=ReplyFormat(reply_format),
        give_up_after=give_up_after if reasoner in LLM_REASONERS else 0,
    )


def graph_context(
    problem: Problem,
    *,
    reasoner: Reasoner,
    recorder: Recorder,
    quality_threshold: float,
    max_retries: int,
    guidance: str | None,
    review: ReviewPolicy | None = None,
    recorded_reviews: Mapping[int, Resolution] | None = None,
    rate_notes: Mapping[str, Mapping[str, tuple[str, int]]] | None = None,
    plan: GuidancePlan | None = None,
    model_use: ModelUse | None = None,
) -> GraphContext:
    """The LTAA graph's run context, with exact regret always, guidance on request, and the
    review gate when the run has a review policy (or replays recorded resolutions).

    A guided timed run follows `plan` (a durable run's stored plan) or, without one, the
    plan solved here; its problem then decides in the plan's order."""
    oracle: CompletionOracle | UnitOracle
    regret: Regret
    if problem.instance.has_teams:
        # docs/allocation.md#teams: the exact optimum over task units (optimal's flow).
        oracle = units = UnitOracle(problem)
        regret = units.regret
    else:
        oracle = single = CompletionOracle(problem)

        def regret(task_index: int, loads: Sequence[int], members: tuple[int, ...]) -> float:
            return single.regret(task_index, loads, members[0])

    def cost(task_index: int, loads: Sequence[int], robot: int) -> float | None:
        # Success points over the rest of the queue: the unit of the guidance costs.
        loss = oracle.loss(task_index, loads, robot)
        return None if loss is None else loss * 100

    gate = (
        ReviewGate(policy=review, cost=cost, recorded=recorded_reviews)
        if review is not None or recorded_reviews is not None
        else None
    )
    guide: Guidance | None = None
    if guidance == "optimizer" and problem.instance.timed:
        # In time, the `schedule` solver's plan, followed in its order
        # (docs/schedules.md#the-order-of-decisions).
        plan = plan if plan is not None else plan_guidance(problem)
        problem = guided_problem(problem, plan)
        guide = ScheduleGuidance(plan) if plan.robots else None
    elif guidance == "optimizer":
        guide = oracle.guidance
    return GraphContext(
        problem=problem,
        reasoner=reasoner,
        recorder=recorder,
        quality_threshold=quality_threshold,
        max_retries=max_retries,
        guidance=guide,
        # The oracle's regret counts the tasks after this one in queue order; a timed run
        # decides in time order, so its decisions record no regret.
        regret=None if problem.instance.timed else regret,
        review=gate,
        rate_notes=rate_notes or {},
        model_use=model_use or ModelUse(),
    )


def execute_ltaa(
    problem: Problem,
    *,
    graph: CompiledStateGraph[Any, Any, Any, Any],
    thread_id: str,
    reasoner: Reasoner,
    recorder: Recorder,
    quality_threshold: float,
    max_retries: int,
    guidance: str | None,
    resume: bool = False,
    review: ReviewPolicy | None = None,
    recorded_reviews: Mapping[int, Resolution] | None = None,
    resume_with: Any = None,
    rate_notes: Mapping[str, Mapping[str, tuple[str, int]]] | None = None,
    plan: GuidancePlan | None = None,
    model_use: ModelUse | None = None,
) -> Execution:
    """The one execution path of an LTAA problem (durable runs, `ltaa run` and the
    synchronous solver): its context with exact regret (and guidance on request), then
    app.graph.execution.execute. Closes `reasoner`; raises GraphEndedEarly if the graph
    returned before every task was decided."""
    context = graph_context(
        problem,
        reasoner=reasoner,
        recorder=recorder,
        quality_threshold=quality_threshold,
        max_retries=max_retries,
        guidance=guidance,
        review=review,
        recorded_reviews=recorded_reviews,
        rate_notes=rate_notes,
        plan=plan,
        model_use=model_use,
    )
    return execute(graph, context, thread_id, resume=resume, resume_with=resume_with)


GRAPH_TIMES = "the LTAA graph's own times: decided in time order, each task placed when chosen"


def graph_times(
    problem: Problem, assignment: Sequence[int], decisions: Sequence[DecisionRecord]
) -> dict[str, Any]:
    """On a timed instance, the schedule the graph made as it decided
    (docs/schedules.md#runs-in-time), which the list-scheduler hook then leaves alone; nothing
    untimed. Pins without a recorded start are placed as the graph placed them; a team task
    sits in every member's lane (docs/allocation.md#teams)."""
    if not problem.instance.timed:
        return {}
    starts = {d.task_index: d.start for d in decisions if d.start is not None}
    teams = {**problem.pinned_teams, **decision_teams(problem, decisions)}
    placed = TimedProgress.replay(problem, dict(enumerate(assignment)), teams=teams).placed
    n = problem.instance.n_tasks
    schedule = build_schedule(
        problem,
        list(assignment),
        [float(starts.get(t, placed[t].start)) for t in range(n)],
        teams=teams,
    )
    return {
        "schedule": schedule,
        "schedule_model": GRAPH_TIMES,
        "schedule_violations": check_schedule(problem, schedule),
    }


class LTAASolver(Solver):
    info = SolverInfo(
        name="ltaa",
        description="The LTAA graph (phase detection, reasoning, 8-criterion validation, tiered "
        "retries, rules fallback), run synchronously; reasoner 'rules' (default), "
        "'anthropic' or 'openai' (an OpenAI-compatible server, e.g. vLLM or Ollama).",
        exact=False,
        limits="any size within the request limits; 'anthropic' and 'openai' make 1-4 API calls "
        "per task (per contested task with llm_scope 'contested')",
    )
    Options = LTAAOptions
    # docs/allocation.md#teams: the graph forms teams, in time too (its time lines place a
    # team in every member's lane: app.domain.scheduling.progress).
    forms_teams = True

    def _solve(self, problem: Problem, *, seed: int, options: Any) -> Solution:
        opts: LTAAOptions = options
        reply_format = str(
            opts.reply_format
            or getattr(self.settings, "llm_reply_format", ReplyFormat.JSON_SCHEMA.value)
        )
        try:
            reasoner = make_reasoner(
                opts.reasoner,
                settings=self.settings,
                model=opts.model,
                temperature=opts.temperature,
                timeout=opts.timeout,
                llm_scope=opts.llm_scope,
                llm_margin=opts.llm_margin,
                reply_format=reply_format,
            )
        except DomainError as exc:
            raise DomainError("options.reasoner", exc.message, code=exc.code) from None
        recorder = MemoryRecorder()
        # Solved here rather than in graph_context: its order also places the pins without
        # a start in graph_times below, as the graph placed them.
        plan = None
        if opts.guidance == "optimizer" and problem.instance.timed:
            plan = plan_guidance(problem)
        try:
            execution = execute_ltaa(
                problem,
                graph=build_graph(InMemorySaver()),
                thread_id=uuid.uuid4().hex,
                reasoner=reasoner,
                recorder=recorder,
                quality_threshold=opts.quality_threshold,
                max_retries=opts.max_retries,
                guidance=opts.guidance,
                plan=plan,
                model_use=model_use_for(
                    opts.reasoner, reply_format, getattr(self.settings, "llm_give_up_after", 0)
                ),
            )
        except DomainError as exc:
            # e.g. the Messages API refusing the model: point at the request's option.
            err = DomainError(f"options.{exc.field}", exc.message, code=exc.code)
            err.status_code = exc.status_code
            raise err from exc
        decisions, used = execution.decisions, execution.usage
        # The graph decides the free tasks only; pins complete the assignment.
        assignment = problem.complete([d.robot for d in decisions])
        return Solution(
            assignment,
            teams=decision_teams(problem, decisions),
            usage=used,
            details={
                **graph_times(
                    problem if plan is None else guided_problem(problem, plan),
                    assignment,
                    decisions,
                ),
                "reasoner": reasoner.name,
                # None when every task is pinned: the graph decided nothing.
                "mean_quality": (
                    round(statistics.fmean(d.quality for d in decisions), 4) if decisions else None
                ),
                "fallbacks": sum(d.fallback for d in decisions),
                "retries": sum(d.attempts - 1 for d in decisions),
                "transport_retries": used.transport_retries,
                "guidance": opts.guidance,
                "llm_scope": opts.llm_scope,
                "regret": sum(d.regret or 0.0 for d in decisions),
                "decisions": [
                    {
                        "task_index": d.task_index,
                        "robot": d.robot_name,
                        "phase": d.phase,
                        "quality": d.quality,
                        "attempts": d.attempts,
                        "fallback": d.fallback,
                        "regret": d.regret,
                        "confidence": d.confidence,
                        **({"team": d.team} if d.team else {}),
                    }
                    for d in decisions
                ],
            },
        )
