"""GET /runs/{id}'s assignments, each rendered once per process.

A poll answers with a page of up to 1,000 assignments, and site software polls a run every
half second. Rendered row by row on every poll (read, decoded, validated, rounded, encoded),
the page cost a 1,000-task run half again its own CPU. A stored decision never changes (a
resumed node rewrites it with the same values; a revision is another run), so its JSON is
kept here, keyed by run and task, and a poll renders only the decisions it has not seen.
The one part of an assignment that moves, its execution report, is never kept: an
assignment with one is rendered on each poll.

The answer is the same JSON, byte for byte in every value, as RoundedJSONResponse makes of
the whole RunOut: the kept pieces are rendered by that same model and rounding, and spliced
into the rest of the body.
"""

from __future__ import annotations

import json
import threading
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from fastapi import Response

from app.graph.recorder import DecisionRecord
from app.http.rounding import rounded
from app.runs.schemas import RunAssignment, RunOut
from app.runs.views import RunView

# Runs whose assignments are kept (least recently polled dropped first): a few MB at most.
KEPT_RUNS = 16
_EMPTY = b'"assignments":[]'


def _encode(content: Any) -> bytes:
    """As starlette's JSONResponse.render (what RoundedJSONResponse calls after rounding)."""
    return json.dumps(
        rounded(content), ensure_ascii=False, allow_nan=False, indent=None, separators=(",", ":")
    ).encode("utf-8")


class AssignmentPages:
    """The rendered assignments of the runs polled lately: run id -> task index -> JSON."""

    def __init__(self, runs: int = KEPT_RUNS) -> None:
        self._runs = runs
        self._kept: OrderedDict[str, dict[int, bytes]] = OrderedDict()
        self._lock = threading.Lock()

    def kept(self, run_id: str) -> dict[int, bytes]:
        """The assignments of `run_id` kept so far (a copy: the caller's read and render
        use one set, whatever other polls keep or drop meanwhile)."""
        with self._lock:
            kept = self._kept.get(run_id)
            if kept is None:
                return {}
            self._kept.move_to_end(run_id)
            return dict(kept)

    def response(
        self,
        view: RunView,
        head: RunOut,
        kept: Mapping[int, bytes],
        assignment: Callable[[DecisionRecord], RunAssignment],
    ) -> Response:
        """`head` (a RunOut with no assignments) with the page's assignments in page order:
        `kept` ones as they are, the view's decisions rendered by `assignment` (and kept
        unless they have an execution report)."""
        loaded = {d.task_index: d for d in view.decisions}
        pieces: list[bytes] = []
        fresh: dict[int, bytes] = {}
        for t in view.page:
            record = loaded.get(t)
            if record is None:
                pieces.append(kept[t])
                continue
            piece = _encode(assignment(record).model_dump(mode="json"))
            if t not in view.execution:
                fresh[t] = piece
            pieces.append(piece)
        if fresh:
            self._keep(view.run.id, fresh)
        return Response(
            _splice(_encode(head.model_dump(mode="json")), pieces), media_type="application/json"
        )

    def _keep(self, run_id: str, fresh: dict[int, bytes]) -> None:
        with self._lock:
            kept = self._kept.setdefault(run_id, {})
            kept.update(fresh)
            self._kept.move_to_end(run_id)
            while len(self._kept) > self._runs:
                self._kept.popitem(last=False)


def _splice(head: bytes, pieces: Sequence[bytes]) -> bytes:
    """`head`'s empty assignments list filled with `pieces`. The first match is the field:
    a JSON string escapes its quotes, so no string holds `"assignments":[]` unescaped, and
    the fields before it (ids, names, progress, the workload's integers) hold no list."""
    at = head.index(_EMPTY)
    return b"".join((head[: at + len(_EMPTY) - 1], b",".join(pieces), head[at + len(_EMPTY) - 1 :]))
