"""The graph version is derived from the node set, the state schema and the behaviour
constant, not the package version."""

from __future__ import annotations

import re

from fastapi.testclient import TestClient

from app.config import Settings
from app.graph import version
from app.graph.builder import NODES
from app.main import create_app


def test_the_version_covers_nodes_state_and_behaviour() -> None:
    fingerprint = version._fingerprint()
    assert fingerprint["nodes"] == list(NODES)
    assert fingerprint["state"]["task_index"] == "int"  # type: ignore[index]
    assert "guided_costs" in fingerprint["view"]  # type: ignore[operator]
    assert fingerprint["behaviour"] == version.BEHAVIOUR_VERSION
    assert re.fullmatch(r"g[0-9]+-[0-9a-f]{12}", version.GRAPH_VERSION)
    assert version._derive() == version.GRAPH_VERSION  # deterministic


def test_a_changed_node_set_changes_the_version() -> None:
    before = version._derive()
    NODES["extra"] = NODES["retry"]
    try:
        assert version._derive() != before
    finally:
        del NODES["extra"]
    assert version._derive() == before


def test_compatibility_and_the_test_seam() -> None:
    assert version.compatible("g1-a", "g1-a")
    assert not version.compatible("g1-a", "g1-b")
    assert version.compatible(None, "g1-b")  # runs from before versions were recorded
    assert version.current_version() == version.GRAPH_VERSION
    assert version.current_version("g9-test") == "g9-test"
    message = version.upgrade_blocked_message("g1-a", "g1-b")
    assert "g1-a" in message and "g1-b" in message and "revise" in message


def test_health_reports_the_graph_version(settings: Settings) -> None:
    with TestClient(create_app(settings)) as client:
        assert client.get("/health").json()["graph_version"] == version.GRAPH_VERSION
    seam = settings.model_copy(update={"test_graph_version": "g9-seam"})
    with TestClient(create_app(seam)) as client:
        assert client.get("/health").json()["graph_version"] == "g9-seam"
