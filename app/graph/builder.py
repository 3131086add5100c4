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
from app.graph.state import GraphContext, LTAAState


def route_after_validate(state: LTAAState) -> str:
    return "finalize" if state.get("accepted") else "build_feedback"


def route_after_retry(state: LTAAState) -> str:
    return "finalize" if state.get("fallback") else "reason"


def route_after_store(state: LTAAState) -> str:
    return END if state.get("done") else "detect_phase"


def build_graph(
    checkpointer: BaseCheckpointSaver[Any] | None = None,
) -> CompiledStateGraph[Any, Any, Any, Any]:
    """Compile the graph. Call once per process (or per synchronous solve), never at import."""
    g = StateGraph(LTAAState, context_schema=GraphContext)
    g.add_node("detect_phase", nodes.detect_phase)
    g.add_node("build_prompt", nodes.build_prompt)
    g.add_node("reason", nodes.reason)
    g.add_node("validate", nodes.validate)
    g.add_node("build_feedback", nodes.build_feedback)
    g.add_node("retry", nodes.retry)
    g.add_node("finalize", nodes.finalize)
    g.add_node("update_workload", nodes.update_workload)
    g.add_node("store_and_route", nodes.store_and_route)

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
