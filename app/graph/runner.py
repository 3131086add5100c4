"""The small API the durable run service and the synchronous solver call."""

from __future__ import annotations

from typing import Any

from langgraph.graph.state import CompiledStateGraph
from langgraph.types import Command, Interrupt, RunnableConfig

from app.graph.state import GraphContext, initial_state

__all__ = ["GraphContext", "initial_state", "recursion_limit", "run_graph", "thread_config"]

# Super-steps of one task with no retry: detect_phase, build_prompt, reason, validate,
# finalize, update_workload, store_and_route, plus build_feedback and retry after the
# last failed attempt before a fallback.
STEPS_PER_TASK = 9
STEPS_PER_RETRY = 4  # build_feedback, retry, reason, validate


def recursion_limit(n_tasks: int, max_retries: int) -> int:
    """The worst case: every task exhausts its retries (docs/allocation.md#the-recursion-limit),
    plus one."""
    return (STEPS_PER_TASK + STEPS_PER_RETRY * max_retries) * n_tasks + 1


def thread_config(thread_id: str, n_tasks: int, max_retries: int) -> RunnableConfig:
    return {
        "configurable": {"thread_id": thread_id},
        "recursion_limit": recursion_limit(n_tasks, max_retries),
    }


def has_checkpoint(graph: CompiledStateGraph[Any, Any, Any, Any], thread_id: str) -> bool:
    saver = graph.checkpointer
    if saver is None or saver is True or saver is False:
        return False
    return saver.get_tuple({"configurable": {"thread_id": thread_id}}) is not None


def pending_interrupt(graph: CompiledStateGraph[Any, Any, Any, Any], thread_id: str) -> Any:
    """The payload of the interrupt the thread is paused at, or None."""
    if not has_checkpoint(graph, thread_id):
        return None
    interrupts = graph.get_state({"configurable": {"thread_id": thread_id}}).interrupts
    return interrupts[0].value if interrupts else None


INTERRUPT_KEY = "__interrupt__"


def run_graph(
    graph: CompiledStateGraph[Any, Any, Any, Any],
    context: GraphContext,
    thread_id: str,
    *,
    resume: bool,
    resume_with: Any = None,
) -> dict[str, Any]:
    """Run (or resume) the thread to the end, or to an `interrupt()`, and return the final
    graph state (with `__interrupt__` when it paused).

    Resuming must pass None as input: passing the initial state again restarts from START
    and duplicates work. A resume of a thread that never reached its first checkpoint
    starts it fresh; starting a thread that already has checkpoints is refused.
    A thread paused at an interrupt is resumed with `Command(resume=resume_with)`; without
    a value it is left paused, not re-run (invoke(None) would re-run the paused node).
    """
    n = len(context.problem.free_tasks)  # pinned tasks take no super-step
    config = thread_config(thread_id, n, context.max_retries)
    exists = has_checkpoint(graph, thread_id)
    if not resume and exists:
        raise ValueError(
            f"thread {thread_id!r} already has checkpoints; resume it instead of starting it again"
        )
    payload: Any = None if resume and exists else initial_state(context.problem)
    if resume and exists:
        pending = pending_interrupt(graph, thread_id)
        if pending is not None and resume_with is None:
            return {INTERRUPT_KEY: [Interrupt(value=pending)]}
        if pending is not None:
            payload = Command(resume=resume_with)
    result = graph.invoke(payload, config, context=context, durability="sync")
    return dict(result)
