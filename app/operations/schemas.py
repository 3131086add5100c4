"""Answer bodies of the service's own endpoints (health)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field


class HealthOut(BaseModel):
    status: Literal["ok"] = "ok"
    version: str
    graph_version: str = Field(
        description="The graph version runs start under here (app.graph.version); a run "
        "interrupted under another resumes only under that one"
    )
    solvers: list[str]
    default_reasoner: str
