"""The one way an LTAA problem is executed against a compiled graph and a recorder.

Used by the synchronous `ltaa` solver (in memory), the durable run worker and `ltaa run`
(both through app.solvers.ltaa.execute_ltaa): the reasoner's lifetime, the recursion
limit, resume-or-start and the completeness check live here once.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from langgraph.graph.state import CompiledStateGraph

from app.domain.usage import Usage
from app.graph.recorder import DecisionRecord
from app.graph.runner import INTERRUPT_KEY, run_graph
from app.graph.state import GraphContext
from app.reasoners.base import close_reasoner


@dataclass(frozen=True)
class Execution:
    """How an execution ended: every decision, in task order, and what its LLM calls used
    (from the record, so a resumed run counts each call once)."""

    decisions: list[DecisionRecord]
    usage: Usage
    # Set when the graph paused at a review (`interrupt()`): the interrupt's payload. The
    # thread waits for `Command(resume=...)`; the decisions are those stored so far.
    paused: dict[str, Any] | None = None


class GraphEndedEarly(RuntimeError):
    """The graph returned before every task had a stored decision (a router that raised,
    LangGraph #8834): completion is judged by the record, never by the graph returning."""

    def __init__(self, stored: int, total: int) -> None:
        super().__init__(f"graph ended with {stored} of {total} decisions stored")
        self.stored = stored
        self.total = total


def execute(
    graph: CompiledStateGraph[Any, Any, Any, Any],
    context: GraphContext,
    thread_id: str,
    *,
    resume: bool,
    resume_with: Any = None,
) -> Execution:
    """Run (or resume) the thread to its end, or until it pauses for a review; its
    decisions and usage. `resume_with`: a review's resolution, for a paused thread.

    Takes ownership of `context.reasoner`: it is closed (its HTTP pool, for the LLM
    reasoners) however the execution ends. RunCancelled and reasoner errors propagate.
    """
    try:
        result = (
            run_graph(graph, context, thread_id, resume=resume, resume_with=resume_with)
            if context.problem.free_tasks  # every task pinned: nothing for the graph to decide
            else {}
        )
    finally:
        close_reasoner(context.reasoner)
    decisions = context.recorder.decisions()
    interrupts = result.get(INTERRUPT_KEY)
    if interrupts:
        return Execution(
            decisions=decisions, usage=context.recorder.usage(), paused=dict(interrupts[0].value)
        )
    problem = context.problem
    # Pins are decided before the graph runs (a revision's own rows) or not recorded at all
    # (/allocate `pinned`): the graph is complete when every free task has its decision.
    decided = [d.task_index for d in decisions if d.task_index not in problem.pinned]
    if decided != list(problem.free_tasks):
        raise GraphEndedEarly(len(decided), len(problem.free_tasks))
    return Execution(decisions=decisions, usage=context.recorder.usage())
