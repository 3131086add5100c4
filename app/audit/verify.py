"""Verify a run's record: recompute its hash chains (decisions, events, annotations) by the
run's own chain scheme, the link to a revision's parent, the sign-offs' heads and the
signature over the heads."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from app.audit.heads import chain_heads
from app.audit.heads import geneses as chain_geneses
from app.audit.record_pages import (
    annotation_pages,
    columns,
    decision_pages,
    event_pages,
    run_or_missing,
)
from app.audit.signing import SignatureCheck, SigningKeys, check_signature
from app.audit.snapshot import Snapshot, snapshot
from app.domain.annotations import AnnotationKind
from app.domain.lifecycle import EventKind, RunStatus
from app.store import chain
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.models import Attempt, Decision, RunAnnotation, RunEvent


@dataclass(frozen=True)
class ChainCheckResult:
    rows: int
    unchained: int
    head: str | None  # the newest row's stored hash: what a supervisor records at sign-off
    first_break: chain.Break | None


@dataclass(frozen=True)
class ParentLink:
    """How a revision hangs off its parent (docs/living-plans.md#audit): checked by trace/verify."""

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
        run = run_or_missing(session, run_id)
        status, n_tasks, anchor = run.status, run.n_tasks, run.chain_anchor
        geneses = chain_geneses(run)
        scheme = run.chain_scheme or chain.SCHEME
        signature_row = repo.latest_signature(session=session, run_id=run_id)
        revision_of = run.revision_of
        # Everything below is judged as of this one moment, read after the status (so a
        # completed run's rows are all in it): a live run appends while the pages are read.
        seen = snapshot(session, run_id, revision_of)
        order = seen.order

    decisions = _decision_chain(sessions, run_id, seen, anchor, geneses["decisions"])
    events, last_kind = _event_chain(sessions, run_id, seen, anchor, geneses["events"])
    _check_tails(status, n_tasks, order, decisions, events, last_kind)
    annotations, signed = _annotation_chain(sessions, run_id, seen)
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


def _decision_chain(
    sessions: sessionmaker[Session],
    run_id: str,
    seen: Snapshot,
    anchor: str | None,
    genesis: str | None,
) -> chain.ChainCheck:
    decisions = chain.ChainCheck(
        "decisions",
        run_id,
        first_key=0,
        anchor=anchor,
        order=seen.order,
        genesis_link=genesis,
    )
    for chain_pass in seen.passes:
        pages = decision_pages(
            sessions, run_id, chain_pass.pinned, chain_pass.by_seq, last=chain_pass.last
        )
        for page in pages:
            for d, attempts in page:

                def link(prev: str, d: Decision = d, attempts: list[Attempt] = attempts) -> str:
                    digest = chain.attempts_digest(
                        columns(a, chain.ATTEMPT_FIELDS) for a in attempts
                    )
                    return chain.decision_link(prev, chain.decision_columns(d), digest)

                decisions.feed(d.task_index, d.chain_hash, link)
    return decisions


def _event_chain(
    sessions: sessionmaker[Session],
    run_id: str,
    seen: Snapshot,
    anchor: str | None,
    genesis: str | None,
) -> tuple[chain.ChainCheck, str | None]:
    """The events' check and the kind of the last event."""
    events = chain.ChainCheck("events", run_id, first_key=1, anchor=anchor, genesis_link=genesis)
    last_kind = None
    for event_page in event_pages(sessions, run_id, last=seen.last_event):
        for e in event_page:

            def event_link(prev: str, e: RunEvent = e) -> str:
                return chain.event_link(prev, columns(e, chain.EVENT_FIELDS))

            events.feed(e.seq, e.chain_hash, event_link)
            last_kind = e.kind
    return events, last_kind


def _check_tails(
    status: str,
    n_tasks: int,
    order: list[int] | None,
    decisions: chain.ChainCheck,
    events: chain.ChainCheck,
    last_kind: str | None,
) -> None:
    """The newest rows of a chain leave no gap when deleted; a completed run says where its
    chains end (n_tasks decisions, and its last event is the one that completed it)."""
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


def _annotation_chain(
    sessions: sessionmaker[Session], run_id: str, seen: Snapshot
) -> tuple[chain.ChainCheck, list[Any]]:
    """The annotations' check and the heads each sign-off signed."""
    annotations = chain.ChainCheck("annotations", run_id, first_key=1)
    signed: list[Any] = []
    for annotation_page in annotation_pages(sessions, run_id, last=seen.last_annotation):
        for a in annotation_page:
            if a.kind == AnnotationKind.SIGNOFF:
                signed.append((a.detail or {}).get("heads"))

            def annotation_link(prev: str, a: RunAnnotation = a) -> str:
                return chain.annotation_link(prev, columns(a, chain.ANNOTATION_FIELDS))

            annotations.feed(a.seq, a.chain_hash, annotation_link)
    return annotations, signed


def check_parent_link(
    *, sessions: sessionmaker[Session], run_id: str, parent_id: str
) -> ParentLink:
    """A revision's first event is `revised`, its chains start from the digest of that
    event's link (the parent's heads and the change set), the parent names it as
    `superseded_by`, and the parent's chains still hold the heads it was revised at."""

    def bad(reason: str) -> ParentLink:
        return ParentLink(parent=parent_id, ok=False, reason=reason)

    with sessions() as session:
        run = run_or_missing(session, run_id)
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
        parent_decisions = decision_repo.decisions(session=session, run_id=parent_id)
        # The head in chain order (a revised revision's pins first); revisions made before
        # that was fixed recorded the parent's last decision in task order, which is the
        # same link unless the parent's last task was pinned: both still prove the parent's
        # chain holds what the revision started from.
        heads_now = {
            chain_heads(session, parent_id).decision_hash,
            parent_decisions[-1].chain_hash if parent_decisions else None,
        }
        if heads.get("decisions") not in heads_now:
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
