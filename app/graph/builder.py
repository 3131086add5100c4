"""The LTAA graph: all nine nodes and every edge, in one place (paper Fig. 5).

    detect_phase -> build_prompt -> reason -> validate --accepted--> finalize
    validate --rejected--> build_feedback -> retry --next tier--> reason
    retry --retries exhausted--> finalize (rules fallback)
    finalize -> update_workload -> store_and_route --more tasks--> detect_phase | END

Routers read one state flag each and cannot raise: a raising router ends a resumed run
silently (LangGraph bug #8834).
"""

from __future__ import annotations

from typing import Any

from langgraph.checkpoint.base import BaseCheckpointSaver
from langgraph.graph import END, START, StateGraph
from langgraph.graph.state import CompiledStateGraph

from app.graph import nodes
from app.graph.pause import NodeHook
from app.graph.state import GraphContext, LTAAState, Node

# The node every task begins with: where a durable run's checkpoints are written
# (app.graph.checkpoint._sparse), so a resume starts the task it was killed in again.
TASK_START = "detect_phase"

NODES: dict[str, Node] = {
    "detect_phase": nodes.detect_phase,
    "build_prompt": nodes.build_prompt,
    "reason": nodes.reason,
    "validate": nodes.validate,
    "build_feedback": nodes.build_feedback,
    "retry": nodes.retry,
    "finalize": nodes.finalize,
    "update_workload": nodes.update_workload,
    "store_and_route": nodes.store_and_route,
}


def route_after_validate(state: LTAAState) -> str:
    return "finalize" if state.get("accepted") else "build_feedback"


def route_after_retry(state: LTAAState) -> str:
    return "finalize" if state.get("fallback") else "reason"


def route_after_store(state: LTAAState) -> str:
    return END if state.get("done") else "detect_phase"


def build_graph(
    checkpointer: BaseCheckpointSaver[Any] | None = None,
    *,
    node_hook: NodeHook | None = None,
) -> CompiledStateGraph[Any, Any, Any, Any]:
    """Compile the graph. Call once per process (or per synchronous solve), never at import.

    `node_hook(name, node)` may wrap nodes (the test-only pause points of app.graph.pause).
    """
    g = StateGraph(LTAAState, context_schema=GraphContext)
    for name, node in NODES.items():
        g.add_node(name, node_hook(name, node) if node_hook is not None else node)

    g.add_edge(START, "detect_phase")
    g.add_edge("detect_phase", "build_prompt")
    g.add_edge("build_prompt", "reason")
    g.add_edge("reason", "validate")
    g.add_conditional_edges("validate", route_after_validate, ["finalize", "build_feedback"])
    g.add_edge("build_feedback", "retry")
    g.add_conditional_edges("retry", route_after_retry, ["reason", "finalize"])
    g.add_edge("finalize", "update_workload")
    g.add_edge("update_workload", "store_and_route")
    g.add_conditional_edges("store_and_route", route_after_store, ["detect_phase", END])
    return g.compile(checkpointer=checkpointer)
