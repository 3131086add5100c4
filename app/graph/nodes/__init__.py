"""The nine LTAA nodes (docs/allocation.md#the-ltaa-graph). Each starts by checking for
cancellation, and every side effect is an idempotent upsert: LangGraph re-runs an interrupted node
from its top."""

from app.graph.nodes.feedback import build_feedback
from app.graph.nodes.finalize import finalize
from app.graph.nodes.phase import detect_phase
from app.graph.nodes.prompt import build_prompt
from app.graph.nodes.reason import reason
from app.graph.nodes.retry import retry
from app.graph.nodes.store import store_and_route
from app.graph.nodes.validate import validate
from app.graph.nodes.workload import update_workload

__all__ = [
    "build_feedback",
    "build_prompt",
    "detect_phase",
    "finalize",
    "reason",
    "retry",
    "store_and_route",
    "update_workload",
    "validate",
]
