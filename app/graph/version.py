"""The graph version a run starts under, and whether a checkpoint may resume under another.

A checkpoint is the state of one graph: its channels (the state schema) and the node that
runs next. A release that renames a node, adds a channel or decides differently from the
same prompt (prompts, validation) would resume an old checkpoint into a graph it was never
written for. The version is derived from exactly those things, so a release that changes
none of them (a fix in the API, the store, the console) keeps the version and its runs
resume as before; the package version alone would block them for nothing.
"""

from __future__ import annotations

import hashlib
import json

from app.graph.builder import NODES
from app.graph.state import LTAAState, TaskView

# Bump when prompts, parsing or validation change what a resumed task would decide (the
# node set and the state schema are read from the code itself). 2: team decisions
# (docs/allocation.md#teams) and unit-aware candidate lists on instances with team tasks.
# 3: a task with a lead may take idle time before its predecessor on the same robot
# (docs/schedules.md#links), so a timed run with leads places some tasks earlier.
# 4: structured replies (docs/reasoners.md#structured-replies: the run's reply format shapes
# its prompts, and a JSON reply is read against the decision's schema) and the give-up rule
# (docs/reasoners.md#bounded-cost: the `failing` count in the state).
BEHAVIOUR_VERSION = 4


def _annotations(schema: type) -> dict[str, str]:
    # As written in the source (a ForwardRef's text under postponed evaluation): stable,
    # and changed by any edit to a channel's name or type.
    return {
        name: str(getattr(hint, "__forward_arg__", hint))
        for name, hint in schema.__annotations__.items()
    }


def _fingerprint() -> dict[str, object]:
    return {
        "nodes": list(NODES),
        "state": _annotations(LTAAState),
        "view": _annotations(TaskView),
        "behaviour": BEHAVIOUR_VERSION,
    }


def _derive() -> str:
    canonical = json.dumps(_fingerprint(), sort_keys=True, separators=(",", ":"))
    return f"g{BEHAVIOUR_VERSION}-{hashlib.sha256(canonical.encode()).hexdigest()[:12]}"


GRAPH_VERSION = _derive()


def compatible(started_under: str | None, current: str) -> bool:
    """A run may resume under `current` if it started under the same graph. A run from
    before versions were recorded (None) resumes as it always did."""
    return started_under is None or started_under == current


def current_version(override: str | None = None) -> str:
    """This process's graph version; `override` is the test seam (LTAA_TEST_GRAPH_VERSION)."""
    return override or GRAPH_VERSION


def upgrade_blocked_message(started_under: str, current: str) -> str:
    return (
        f"not resumed: this run started under graph version {started_under} and this "
        f"server runs graph version {current}; its checkpoint cannot be resumed by another "
        f"graph. Either finish it with a release of graph version {started_under} (then "
        "POST /runs/{id}/resume there), or revise it: start a new run from its record "
        "(issue 8's revisions) or with the same request. It stays blocked, claimed by no "
        "worker, until then."
    )
