"""Tamper evidence for a run's audit record: every decision and event row carries a SHA-256
hash over its audited content and the hash of the previous row of its run (a hash chain).

Two chains per run, one per table. Decisions are linked in `task_index` order and events in
`seq` order, each starting from a genesis value derived from the table and the run id.
A third, `annotations`, links what is recorded about a run after it finished (sign-offs),
in `seq` order: a completed run's decision and event chains never change, so a sign-off
can name their heads, and the annotations that follow stay checkable too.
Why not one chain over both tables: events are written by the run service and worker and
decisions by the graph's store node, at unrelated moments (and, on PostgreSQL, possibly from
different processes); one interleaved chain would need a global order across both tables and
a second lookup per write. Per-table chains need one indexed lookup of the previous row, and
the genesis ties every link to its run and table, so a row copied in from another run, or an
event passed off as a decision, never verifies.

What a link covers (`DECISION_FIELDS`, `ATTEMPT_FIELDS`, `EVENT_FIELDS`): every column an
auditor reads. A decision's link also folds in a digest of its task's attempts (prompts,
replies, per-criterion scores, verdicts), so the attempts supervisors read are covered too;
they are written before the decision, so the digest is final when the decision is stored.
Left out: surrogate ids, `run_id` (in the genesis) and timestamps; a decision re-upserted
after a crash gets a new `created_at` but must keep its hash, since the content is the same.

Canonical form: JSON with sorted keys and no whitespace; floats as `repr` (shortest
round-trip form) after `float()`, with -0.0 as 0.0 and NaN as null (SQLite stores them that
way, so a value must hash the same before and after a round trip through the table); JSON
columns are hashed in the form the table returns (a tuple reads back as a list, an integer
key as a string).

What verification detects: an edited audited column or attempt (the row's link no longer
matches), a deleted row (a gap in task_index/seq, or, for the newest rows of a completed
run, a missing decision or a missing final event), and reordered rows (the index is part of
the content, so a swapped pair breaks at the first of the two). Rows written before the
chain existed have no hash and are reported as unchained, never as verified.
What it cannot detect on its own: someone with write access to the database who knows this
scheme can recompute every link after an edit, since the chain has no secret key. The
verifier reports each chain's head hash; a supervisor who records the heads at sign-off can
later tell that the record changed, however it was rewritten; with a server signing key the
heads are signed (app.audit.signing), so a rewrite needs the private key to pass.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

Table = Literal["decisions", "events", "annotations"]
# The previous row exists but was written before chaining: later links hang off this marker.
UNCHAINED = "0" * 64
SCHEME = "ltaa-trace-chain/v1"
# v2: each chain's genesis also covers the run's immutable fields (its stored request:
# instance, mode, cap, settings), so a record cannot be moved onto another instance.
# Runs record their scheme (runs.chain_scheme; null is v1) and every scheme verifies.
SCHEME_V2 = "ltaa-trace-chain/v2"
SCHEMES = (SCHEME, SCHEME_V2)


def _int(value: Any) -> int:
    return int(value)


def _str(value: Any) -> str:
    return str(value)


def _opt_str(value: Any) -> str | None:
    return None if value is None else str(value)


def _bool(value: Any) -> bool:
    return bool(value)


def _opt_bool(value: Any) -> bool | None:
    return None if value is None else bool(value)


def _float(value: Any) -> float | None:
    if value is None:
        return None
    number = float(value)
    return None if math.isnan(number) else number + 0.0  # -0.0 + 0.0 == +0.0


def _json(value: Any) -> Any:
    # The form the JSON column returns, whatever Python object was written.
    return json.loads(json.dumps(value))


Normaliser = Callable[[Any], Any]

DECISION_FIELDS: dict[str, Normaliser] = {
    "task_index": _int,
    "task_id": _str,
    "task_name": _str,
    "robot": _int,
    "robot_name": _str,
    "phase": _str,
    "expected_success": _float,
    "reasoning": _str,
    "confidence": _str,
    "tradeoff": _str,
    "quality": _float,
    "fallback": _bool,
    "attempts": _int,
    "failure_log": _json,
    "loads_before": _json,
    "loads_after": _json,
    "balance_before": _float,
    "balance_after": _float,
    "severity_after": _str,
    "regret": _float,
    "review": _json,
}
# Hashed only when set, so decisions stored before the column existed keep their links.
OPTIONAL_DECISION_FIELDS = frozenset({"review"})
# docs/schedules.md#what-a-decision-records, a timed run's decisions: hashed (and exported) only
# when set, as the pin columns, so untimed decisions keep their links and their export lines.
TIME_FIELDS: dict[str, Normaliser] = {
    "start": _float,
    "end": _float,
    "zone": _opt_str,
    "travel": _float,
    "seq": lambda v: None if v is None else int(v),
    "later_by": _float,
}
# docs/allocation.md#teams, a team decision's members ({"robot", "feature"} per unit): hashed only
# when set, so single-robot decisions (and every link written before teams) keep their hashes.
TEAM_FIELDS: dict[str, Normaliser] = {"team": _json}
ATTEMPT_FIELDS: dict[str, Normaliser] = {
    "attempt": _int,
    "tier": _int,
    "system_prompt": _str,
    "user_prompt": _str,
    "reply_text": _opt_str,
    "reply_model": _opt_str,
    "input_tokens": _int,
    "output_tokens": _int,
    "latency_ms": _float,
    "transport_retries": _int,
    "reply_extra": _json,
    "parsed": _json,
    "scores": _json,
    "quality": _float,
    "accepted": _opt_bool,
    "hard_invalid": _opt_str,
    "feedback": _opt_str,
}
# A revision's pinned decisions (docs/living-plans.md#pins) carry these; hashed only when set, so
# every link written before they existed (and every decision the graph makes) keeps its hash.
PIN_FIELDS: dict[str, Normaliser] = {"pinned": _opt_bool, "pinned_from": _opt_str}
EVENT_FIELDS: dict[str, Normaliser] = {"seq": _int, "kind": _str, "detail": _json}
# Records made after a run finished (app.domain.annotations), chained like the events.
ANNOTATION_FIELDS: dict[str, Normaliser] = {"seq": _int, "kind": _str, "detail": _json}


def canonical_json(value: Any) -> str:
    return json.dumps(
        value, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=True
    )


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _content(fields: Mapping[str, Normaliser], row: Mapping[str, Any]) -> dict[str, Any]:
    return {name: normalise(row[name]) for name, normalise in fields.items()}


def immutable_digest(request: Any, mode: str, max_deviation: float | None) -> str:
    """What a v2 genesis covers besides the table and run id: the fields a run never
    changes (not its status or counters)."""
    return _sha256(
        canonical_json(
            {"request": _json(request), "mode": mode, "max_deviation": _float(max_deviation)}
        )
    )


def genesis(
    table: Table,
    run_id: str,
    anchor: str | None = None,
    *,
    scheme: str | None = None,
    immutable: str | None = None,
) -> str:
    """The link the first row of a run's chain hangs off (scheme None is v1). A revision's
    chains also cover its `anchor` (revision_anchor: the parent's heads and the change
    set), so the record across revisions is one linked chain; a v2 chain also covers the
    run's `immutable` fields (immutable_digest)."""
    tail = "" if anchor is None else f"|{anchor}"
    if scheme in (None, SCHEME):
        return _sha256(f"{SCHEME}|{table}|{run_id}{tail}")
    if scheme == SCHEME_V2:
        if immutable is None:
            raise ValueError(f"{SCHEME_V2} needs the run's immutable_digest")
        return _sha256(f"{SCHEME_V2}|{table}|{run_id}|{immutable}{tail}")
    raise ValueError(f"unknown chain scheme {scheme!r}; known: {', '.join(SCHEMES)}")


def run_genesis(
    table: Table,
    run_id: str,
    *,
    scheme: str | None,
    request: Any,
    mode: str,
    max_deviation: float | None,
    anchor: str | None = None,
) -> str:
    """The genesis of a run's chain from the run's own columns, whatever its scheme."""
    immutable = None if scheme in (None, SCHEME) else immutable_digest(request, mode, max_deviation)
    return genesis(table, run_id, anchor, scheme=scheme, immutable=immutable)


def revision_link(detail: Mapping[str, Any]) -> dict[str, Any]:
    """The part of a `revised` event's detail that a revision's chains are anchored to."""
    keys = ("parent", "parent_heads", "changes", "pin", "reason")
    return {k: detail.get(k) for k in keys}


def revision_anchor(link: Mapping[str, Any]) -> str:
    """Digest of what ties a revision to its parent: the parent id, its chain heads when
    the revision was made, the changes, the pin rule and the reason (the `revised` event's
    detail)."""
    return _sha256(canonical_json(_json(dict(link))))


def decision_columns(row: Any) -> dict[str, Any]:
    """The hashed columns of a stored decision row (pin columns included when set)."""
    values = {name: getattr(row, name) for name in DECISION_FIELDS}
    for name in (*PIN_FIELDS, *TIME_FIELDS, *TEAM_FIELDS):
        value = getattr(row, name, None)
        if value is not None:
            values[name] = value
    return values


def attempts_digest(attempts: Iterable[Mapping[Any, Any]]) -> str:
    """One task's attempts, in attempt order."""
    return _sha256(canonical_json([_content(ATTEMPT_FIELDS, a) for a in attempts]))


def decision_link(prev: str, decision: Mapping[str, Any], attempts: str) -> str:
    """`decision`: the DECISION_FIELDS columns; `attempts`: attempts_digest of its task."""
    content = {
        name: normalise(decision.get(name))
        for name, normalise in DECISION_FIELDS.items()
        if name not in OPTIONAL_DECISION_FIELDS or decision.get(name) is not None
    }
    for name, normalise in (*PIN_FIELDS.items(), *TIME_FIELDS.items(), *TEAM_FIELDS.items()):
        if decision.get(name) is not None:
            content[name] = normalise(decision[name])
    return _sha256(canonical_json({"prev": prev, "decision": content, "attempts": attempts}))


def event_link(prev: str, event: Mapping[str, Any]) -> str:
    """`event`: the EVENT_FIELDS columns."""
    return _sha256(canonical_json({"prev": prev, "event": _content(EVENT_FIELDS, event)}))


def annotation_link(prev: str, annotation: Mapping[str, Any]) -> str:
    """`annotation`: the ANNOTATION_FIELDS columns."""
    content = _content(ANNOTATION_FIELDS, annotation)
    return _sha256(canonical_json({"prev": prev, "annotation": content}))


def next_prev(stored: str | None) -> str:
    """What the row after one with this stored hash links to."""
    return stored if stored is not None else UNCHAINED


@dataclass(frozen=True)
class Break:
    """The first link of a chain that does not verify."""

    table: Table
    key: int  # task_index for decisions, seq for events
    expected: str | None
    stored: str | None
    reason: str


class ChainCheck:
    """Walks one run's chain row by row, in key order, and keeps the first break.

    Rows are fed one at a time so a 10,000-task run is verified in pages, never held whole.
    """

    def __init__(
        self,
        table: Table,
        run_id: str,
        first_key: int,
        *,
        anchor: str | None = None,
        order: list[int] | None = None,
        genesis_link: str | None = None,
    ) -> None:
        """`order`: the keys in chain order when they are not first_key, first_key + 1, ...
        (a revision's decisions: pins first); `anchor`: a revision's link to its parent;
        `genesis_link`: the genesis by the run's chain scheme (run_genesis)."""
        self.table = table
        self.count = 0
        self.unchained = 0
        self.head: str | None = None
        self.last_key: int | None = None
        self.first_break: Break | None = None
        self._prev = genesis_link if genesis_link is not None else genesis(table, run_id, anchor)
        self._order = order
        self._next_key = order[0] if order else first_key
        self._noun = "task_index" if table == "decisions" else "seq"

    def _fail(self, key: int, expected: str | None, stored: str | None, reason: str) -> None:
        if self.first_break is None:
            self.first_break = Break(self.table, key, expected, stored, reason)

    def feed(self, key: int, stored: str | None, link: Callable[[str], str]) -> None:
        """`link(prev)` computes the row's hash given the previous link."""
        self.count += 1
        self.last_key, self.head = key, stored
        if self.first_break is None:
            if key != self._next_key:
                missing = (
                    f"{self._noun} {self._next_key}"
                    if key == self._next_key + 1
                    else f"{self._noun} {self._next_key} to {key - 1}"
                )
                self._fail(
                    self._next_key,
                    None,
                    None,
                    f"{missing} is missing from the {self.table}: the row was deleted "
                    "(or renumbered)",
                )
            elif stored is None:
                self._fail(
                    key,
                    None,
                    None,
                    f"{self._noun} {key} has no chain hash: it was written before "
                    "tamper evidence existed (or its hash was erased), so it cannot be "
                    "verified",
                )
            else:
                expected = link(self._prev)
                if expected != stored:
                    self._fail(
                        key,
                        expected,
                        stored,
                        f"{self._noun} {key} does not match its recorded hash: the row "
                        "was edited, moved, or replaced"
                        + (
                            " (or one of its task's attempts was changed)"
                            if self.table == "decisions"
                            else ""
                        ),
                    )
        if stored is None:
            self.unchained += 1
        self._prev = next_prev(stored)
        if self._order is not None and self.count < len(self._order):
            self._next_key = self._order[self.count]
        else:
            self._next_key = key + 1

    def missing_tail(self, reason: str) -> None:
        """A finished run knows how its chain must end; the caller found it ends early."""
        self._fail(self._next_key, None, None, reason)
