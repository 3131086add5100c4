"""A run's token budget wired to its record (the rule itself: app.reasoners.budget).

The tokens spent so far are read from the stored attempts at every (re)start, and the
switch is written once as a `budget_exhausted` run event, so a run restarted after a
crash switches at the same task and its trace tells the switch once.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from sqlalchemy.orm import Session, sessionmaker

from app.domain.lifecycle import EventKind
from app.reasoners.base import Reasoner
from app.reasoners.budget import BUDGET_EXHAUSTED, BudgetExhausted, TokenBudgetReasoner
from app.runs import lifecycle
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import transaction

log = logging.getLogger("ltaa.runs")


def with_token_budget(
    reasoner: Reasoner,
    *,
    run_id: str,
    budget: int | None,
    sessions: sessionmaker[Session],
    fence: Callable[[Session], None] | None = None,
) -> Reasoner:
    """`reasoner` limited to `budget` tokens for the run; unchanged without a budget.
    `fence` is the recorder's write check (PostgreSQL scale-out): a process that lost the
    run's lease writes no event either."""
    if budget is None:
        return reasoner
    with sessions() as session:
        spent = decision_repo.tokens_spent(session=session, run_id=run_id)

    def record(exhausted: BudgetExhausted) -> None:
        with transaction(sessions) as session:
            if fence is not None:
                fence(session)
            # A run restarted after the switch is told again: the event stays single.
            if repo.has_event(session=session, run_id=run_id, kind=BUDGET_EXHAUSTED):
                return
            lifecycle.record_event(
                session,
                run_id=run_id,
                kind=EventKind.BUDGET_EXHAUSTED,
                detail=exhausted.as_dict(),
            )
        log.warning(
            "token budget spent (%d of %d tokens): the rules reasoner decides from "
            "task index %d on",
            exhausted.tokens_spent,
            exhausted.budget,
            exhausted.task_index,
            extra={"run_id": run_id},
        )

    return TokenBudgetReasoner(reasoner, budget=budget, spent=spent, on_exhausted=record)
