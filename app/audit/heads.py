"""Where a run's chains start and end: the geneses its immutable fields give, and the last
link of each chain as stored. Sign-offs record the heads, signatures sign both."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.store import chain
from app.store.models import Decision, Run, RunEvent


@dataclass(frozen=True)
class ChainHeads:
    decision_hash: str | None
    decisions: int  # decisions chained so far
    event_hash: str | None
    events: int  # events so far (the last seq)

    def as_dict(self) -> dict[str, str | None]:
        return {"decisions": self.decision_hash, "events": self.event_hash}


def chain_heads(session: Session, run_id: str) -> ChainHeads:
    """The last link of each chain. A revision's decisions are chained pins first, then the
    decisions it made (app.store.decision_repository.revision_chain_order), so its head is
    the last decision it made, or its last pin while it has made none; a run without pins
    is chained in task order."""
    last_decision = session.execute(
        select(Decision.chain_hash)
        .where(Decision.run_id == run_id)
        # A timed run's decisions are chained in the order made (seq), others in task order.
        .order_by(
            Decision.pinned.is_(None).desc(),
            func.coalesce(Decision.seq, Decision.task_index).desc(),
        )
        .limit(1)
    ).first()
    decisions = session.scalar(
        select(func.count()).select_from(Decision).where(Decision.run_id == run_id)
    )
    last_event = session.execute(
        select(RunEvent.chain_hash, RunEvent.seq)
        .where(RunEvent.run_id == run_id)
        .order_by(RunEvent.seq.desc())
        .limit(1)
    ).first()
    return ChainHeads(
        decision_hash=last_decision.chain_hash if last_decision else None,
        decisions=int(decisions or 0),
        event_hash=last_event.chain_hash if last_event else None,
        events=last_event.seq if last_event else 0,
    )


def geneses(run: Run) -> dict[str, str]:
    """The genesis of the run's decision and event chains, by its own chain scheme."""
    return {
        table: chain.run_genesis(
            table,
            run.id,
            scheme=run.chain_scheme,
            request=run.request,
            mode=run.mode,
            max_deviation=run.max_deviation,
            anchor=run.chain_anchor,
        )
        for table in ("decisions", "events")
    }
