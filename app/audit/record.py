"""A run's audit record: verify its hash chains, or export it whole as JSON lines.

Both read the record in pages of bounded size, each in its own short session: a 10,000-task
run's prompts and replies are hundreds of megabytes, and a read transaction held open for a
slow download would keep SQLite's WAL from being checkpointed while runs write. Rows are
only ever appended in key order (and a re-upsert rewrites the same content), so reading
by key in pages sees a consistent prefix of a live run.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from app.audit.heads import geneses as chain_geneses
from app.audit.signing import SignatureCheck, SigningKeys, check_signature
from app.domain.annotations import AnnotationKind
from app.domain.lifecycle import EventKind, RunStatus
from app.reasoners.attribution import Attribution, attempt_attribution, decision_attribution
from app.store import chain
from app.store import repository as repo
from app.store.models import Attempt, Decision, Run, RunAnnotation, RunEvent, as_utc
from app.store.tombstones import missing_run

DECISIONS_PER_PAGE = 100  # with their attempts' prompts: about 1-3 MB per page
EVENTS_PER_PAGE = 1000


def _run(session: Session, run_id: str) -> Run:
    run = repo.get_run(session=session, run_id=run_id)
    if run is None:
        raise missing_run(session, run_id)
    return run


def _event_pages(sessions: sessionmaker[Session], run_id: str) -> Iterator[list[RunEvent]]:
    after = 0
    while True:
        with sessions() as session:
            page = repo.events_page(
                session=session, run_id=run_id, after_seq=after, limit=EVENTS_PER_PAGE
            )
        if not page:
            return
        yield page
        after = page[-1].seq


def _annotation_pages(
    sessions: sessionmaker[Session], run_id: str
) -> Iterator[list[RunAnnotation]]:
    after = 0
    while True:
        with sessions() as session:
            page = repo.annotations_page(
                session=session, run_id=run_id, after_seq=after, limit=EVENTS_PER_PAGE
            )
        if not page:
            return
        yield page
        after = page[-1].seq


def _chain_passes(revision_of: str | None) -> tuple[bool | None, ...]:
    """How to read a run's decisions in the order they were chained: all of them in task
    order, or a revision's pins first, then the rest (repo.revision_chain_order)."""
    return (None,) if revision_of is None else (True, False)


def _decision_pages(
    sessions: sessionmaker[Session],
    run_id: str,
    pinned: bool | None = None,
) -> Iterator[list[tuple[Decision, list[Attempt]]]]:
    after = -1
    while True:
        with sessions() as session:
            page = repo.decisions_page(
                session=session,
                run_id=run_id,
                after_task=after,
                limit=DECISIONS_PER_PAGE,
                pinned=pinned,
            )
            if not page:
                return
            attempts = repo.attempts_of_tasks(
                session=session, run_id=run_id, first=page[0].task_index, last=page[-1].task_index
            )
        yield [(d, attempts.get(d.task_index, [])) for d in page]
        after = page[-1].task_index


def _columns(row: Any, fields: dict[str, Any]) -> dict[str, Any]:
    return {name: getattr(row, name) for name in fields}


# -- verification --------------------------------------------------------------------------


@dataclass(frozen=True)
class ChainCheckResult:
    rows: int
    unchained: int
    head: str | None  # the newest row's stored hash: what a supervisor records at sign-off
    first_break: chain.Break | None


@dataclass(frozen=True)
class ParentLink:
    """How a revision hangs off its parent (SPEC 10): checked by trace/verify."""

    parent: str
    ok: bool
    reason: str


@dataclass(frozen=True)
class ChainReport:
    decisions: ChainCheckResult
    events: ChainCheckResult
    annotations: ChainCheckResult
    # Every sign-off's heads are still the heads of the decision and event chains, and
    # those chains verify: what was signed is what the record says now.
    signoffs_ok: bool = True
    parent_link: ParentLink | None = None
    chain_scheme: str = chain.SCHEME
    signature: SignatureCheck | None = None  # the newest signature's check, if any

    @property
    def ok(self) -> bool:
        signed_ok = self.signature is None or self.signature.valid
        parent_ok = self.parent_link is None or self.parent_link.ok
        return self.first_break is None and parent_ok and signed_ok

    @property
    def first_break(self) -> chain.Break | None:
        """The decisions chain's break if it has one, else the events', else the
        annotations'."""
        return self.decisions.first_break or self.events.first_break or self.annotations.first_break


def _result(check: chain.ChainCheck) -> ChainCheckResult:
    return ChainCheckResult(
        rows=check.count, unchained=check.unchained, head=check.head, first_break=check.first_break
    )


def verify_trace(
    *, sessions: sessionmaker[Session], run_id: str, keys: SigningKeys | None = None
) -> ChainReport:
    """Recompute both chains of a run from its rows (by the run's own chain scheme), check
    its newest signature with the public keys, and report the first broken link."""
    with sessions() as session:
        run = _run(session, run_id)
        status, n_tasks, anchor = run.status, run.n_tasks, run.chain_anchor
        geneses = chain_geneses(run)
        scheme = run.chain_scheme or chain.SCHEME
        signature_row = repo.latest_signature(session=session, run_id=run_id)
        revision_of = run.revision_of
        order: list[int] | None = None
        if revision_of is not None:
            # Pins first, then the graph's decisions: the order they were chained in.
            pins = repo.decided_indexes(session=session, run_id=run_id, pinned=True)
            rest = repo.decided_indexes(session=session, run_id=run_id, pinned=False)
            order = repo.revision_chain_order(pins, rest)

    decisions = chain.ChainCheck(
        "decisions",
        run_id,
        first_key=0,
        anchor=anchor,
        order=order,
        genesis_link=geneses["decisions"],
    )
    for pinned in _chain_passes(revision_of):
        for page in _decision_pages(sessions, run_id, pinned):
            for d, attempts in page:

                def link(prev: str, d: Decision = d, attempts: list[Attempt] = attempts) -> str:
                    digest = chain.attempts_digest(
                        _columns(a, chain.ATTEMPT_FIELDS) for a in attempts
                    )
                    return chain.decision_link(prev, chain.decision_columns(d), digest)

                decisions.feed(d.task_index, d.chain_hash, link)

    events = chain.ChainCheck(
        "events", run_id, first_key=1, anchor=anchor, genesis_link=geneses["events"]
    )
    last_kind = None
    for event_page in _event_pages(sessions, run_id):
        for e in event_page:

            def event_link(prev: str, e: RunEvent = e) -> str:
                return chain.event_link(prev, _columns(e, chain.EVENT_FIELDS))

            events.feed(e.seq, e.chain_hash, event_link)
            last_kind = e.kind

    # The newest rows of a chain leave no gap when deleted; a completed run says where its
    # chains end (n_tasks decisions, and its last event is the one that completed it).
    complete = (
        decisions.count == n_tasks if order is not None else decisions.last_key == n_tasks - 1
    )
    if status == RunStatus.COMPLETED and not complete:
        last = "none" if decisions.last_key is None else f"task_index {decisions.last_key}"
        decisions.missing_tail(
            f"the run completed with {n_tasks} tasks but its decisions "
            f"end at {last}: the last decisions were deleted"
        )
    if status == RunStatus.COMPLETED and last_kind != EventKind.COMPLETED:
        events.missing_tail(
            "the run completed but its events do not end with the "
            "'completed' event: the last events were deleted"
        )
    annotations = chain.ChainCheck("annotations", run_id, first_key=1)
    signed: list[Any] = []
    for annotation_page in _annotation_pages(sessions, run_id):
        for a in annotation_page:
            if a.kind == AnnotationKind.SIGNOFF:
                signed.append((a.detail or {}).get("heads"))

            def annotation_link(prev: str, a: RunAnnotation = a) -> str:
                return chain.annotation_link(prev, _columns(a, chain.ANNOTATION_FIELDS))

            annotations.feed(a.seq, a.chain_hash, annotation_link)
    heads_now = {"decisions": decisions.head, "events": events.head}
    chains_intact = decisions.first_break is None and events.first_break is None
    signature = None
    if signature_row is not None:
        signature = check_signature(
            keys or SigningKeys(),
            signature_row.key_id,
            signature_row.payload,
            signature_row.signature,
            heads_now,
            geneses,
        )
    return ChainReport(
        decisions=_result(decisions),
        events=_result(events),
        annotations=_result(annotations),
        signoffs_ok=all(chains_intact and heads == heads_now for heads in signed),
        parent_link=None
        if revision_of is None
        else check_parent_link(sessions=sessions, run_id=run_id, parent_id=revision_of),
        chain_scheme=scheme,
        signature=signature,
    )


def check_parent_link(
    *, sessions: sessionmaker[Session], run_id: str, parent_id: str
) -> ParentLink:
    """A revision's first event is `revised`, its chains start from the digest of that
    event's link (the parent's heads and the change set), the parent names it as
    `superseded_by`, and the parent's chains still hold the heads it was revised at."""

    def bad(reason: str) -> ParentLink:
        return ParentLink(parent=parent_id, ok=False, reason=reason)

    with sessions() as session:
        run = _run(session, run_id)
        first = repo.events_page(session=session, run_id=run_id, after_seq=0, limit=1)
        parent = repo.get_run(session=session, run_id=parent_id)
        if not first or first[0].kind != EventKind.REVISED:
            return bad("the revision's first event is not 'revised'")
        detail = first[0].detail or {}
        if detail.get("parent") != parent_id:
            return bad(f"the 'revised' event names parent {detail.get('parent')!r}")
        if chain.revision_anchor(chain.revision_link(detail)) != run.chain_anchor:
            return bad("the 'revised' event's link does not match the anchor the chains start from")
        if parent is None:
            return bad(f"the parent run {parent_id!r} is missing")
        if parent.superseded_by != run_id:
            return bad(f"the parent names {parent.superseded_by!r} as its revision, not this run")
        heads = detail.get("parent_heads") or {}
        parent_decisions = repo.decisions(session=session, run_id=parent_id)
        head_now = parent_decisions[-1].chain_hash if parent_decisions else None
        if heads.get("decisions") != head_now:
            return bad("the parent's decision chain no longer ends at the head it was revised at")
        if heads.get("events") is not None and not repo.has_event_hash(
            session=session, run_id=parent_id, chain_hash=heads["events"]
        ):
            return bad("the parent's event chain no longer holds the head it was revised at")
    return ParentLink(
        parent=parent_id,
        ok=True,
        reason=f"starts from run {parent_id}'s heads at the revision, which its chains still hold",
    )


# -- export --------------------------------------------------------------------------------


def _when(value: datetime | None) -> str | None:
    return as_utc(value).isoformat() if value is not None else None


def _run_line(run: Run) -> dict[str, Any]:
    return {
        "type": "run",
        "format": run.chain_scheme or chain.SCHEME,
        "chain_scheme": run.chain_scheme or chain.SCHEME,
        "id": run.id,
        "status": run.status,
        "reasoner": run.reasoner,
        "mode": run.mode,
        "max_deviation": run.max_deviation,
        "n_tasks": run.n_tasks,
        "n_robots": run.n_robots,
        "resumes": run.resumes,
        "error": run.error,
        "created_at": _when(run.created_at),
        "finished_at": _when(run.finished_at),
        "request": run.request,
        "revision_of": run.revision_of,
        "revision": run.revision,
        "genesis": chain_geneses(run),
    }


def _event_line(e: RunEvent) -> dict[str, Any]:
    return {
        "type": "event",
        **_columns(e, chain.EVENT_FIELDS),
        "at": _when(e.created_at),
        "chain_hash": e.chain_hash,
    }


def _annotation_line(a: RunAnnotation) -> dict[str, Any]:
    return {
        "type": "annotation",
        **_columns(a, chain.ANNOTATION_FIELDS),
        "at": _when(a.created_at),
        "chain_hash": a.chain_hash,
    }


def _attempt_line(a: Attempt, run_reasoner: str) -> tuple[dict[str, Any], Attribution]:
    who = attempt_attribution(a.reply_extra, a.reply_model, run_reasoner)
    line = {
        **_columns(a, chain.ATTEMPT_FIELDS),
        "at": _when(a.created_at),
        "reasoner": who.reasoner,
        "why": who.why,
    }
    return line, who


def _decision_line(d: Decision, attempts: list[Attempt], run_reasoner: str) -> dict[str, Any]:
    # Columns under their stored names, so the export alone suffices to recompute the chain;
    # `reasoner` and `why` (derived, outside the chain) say who wrote each reply.
    lines = [_attempt_line(a, run_reasoner) for a in attempts]
    accepted = next((who for line, who in reversed(lines) if line["accepted"]), None)
    decided = decision_attribution(bool(d.fallback), accepted)
    return {
        "type": "decision",
        **chain.decision_columns(d),
        "at": _when(d.created_at),
        "chain_hash": d.chain_hash,
        "reasoner": decided.reasoner,
        "why": decided.why,
        "attempt_records": [line for line, _ in lines],
    }


def trace_record(
    *,
    sessions: sessionmaker[Session],
    run_id: str,
) -> Iterator[list[dict[str, Any]]]:
    """The whole audit record as pages of self-describing lines: the run, its events, its
    decisions (each with its attempts, prompts and replies), its annotations (what was
    recorded after it finished: sign-offs, execution reports), then an end line with counts
    so a reader can tell a complete record from a cut-off download.

    Raises RunNotFoundError here, before the first page is asked for."""
    with sessions() as session:
        header = _run_line(_run(session, run_id))
        header["signatures"] = [
            {
                "reason": s.reason,
                "key_id": s.key_id,
                "payload": s.payload,
                "signature": s.signature,
                "at": _when(s.created_at),
            }
            for s in repo.signatures(session=session, run_id=run_id)
        ]
    return _record_pages(sessions, run_id, header)


def _record_pages(
    sessions: sessionmaker[Session], run_id: str, header: dict[str, Any]
) -> Iterator[list[dict[str, Any]]]:
    yield [header]
    n_events = n_decisions = n_attempts = 0
    for events in _event_pages(sessions, run_id):
        n_events += len(events)
        yield [_event_line(e) for e in events]
    # In chain order, so a checker links the lines as they come (a revision: pins first).
    for pinned in _chain_passes(header["revision_of"]):
        for decisions in _decision_pages(sessions, run_id, pinned):
            n_decisions += len(decisions)
            n_attempts += sum(len(a) for _, a in decisions)
            yield [_decision_line(d, a, header["reasoner"]) for d, a in decisions]
    n_annotations = 0
    for annotation_page in _annotation_pages(sessions, run_id):
        n_annotations += len(annotation_page)
        yield [_annotation_line(a) for a in annotation_page]
    yield [
        {
            "type": "end",
            "events": n_events,
            "decisions": n_decisions,
            "attempts": n_attempts,
            "annotations": n_annotations,
        }
    ]
