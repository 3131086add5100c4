"""Replay runs: which run may be replayed, what the replay copies, and its recorded replies.

A replay re-runs a completed run with `reasoner: "replay"`. Everything that decides its
verdicts is copied from the original: the instance, mode, cap, quality threshold,
max_retries, guidance and seed. A request may repeat any of these (it then must equal
the original's) or omit it; `model`, `temperature` and `token_budget` do not apply, since
a replay calls no model and spends no tokens. The review policy is copied with the
recorded resolutions, and a request may not send one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from app.domain.errors import DomainError
from app.domain.lifecycle import RunStatus
from app.reasoners.replay import RecordedReply, ReplyKey
from app.runs.spec import RunSpec
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.models import ArchivedRun

REPLAY = "replay"
# RunSpec fields a replay copies from the original run.
COPIED = (
    "instance_data",
    "mode",
    "max_deviation",
    "quality_threshold",
    "max_retries",
    "guidance",
    "seed",
    "llm_scope",
    "llm_margin",
)
# Request fields that have no meaning for a replay.
NOT_FOR_REPLAY = ("model", "temperature", "token_budget")
# The review policy is copied too, but a request may not even repeat it: the replay
# re-applies the original's recorded resolutions and never waits, so a policy of its own
# would read as a promise of new reviews that cannot happen.
REVIEW = "review"
# Request fields naming the instance; they all map onto the spec's instance_data.
_INSTANCE_FIELDS = ("scenario", "tasks", "robots")


class ReplaySourceNotFinishedError(DomainError):
    status_code = 409

    def __init__(self, run_id: str, status: str) -> None:
        hint = (
            "wait until it completes"
            if status in (RunStatus.QUEUED, RunStatus.RUNNING, RunStatus.INTERRUPTED)
            else "only a completed run has a full record to replay"
        )
        super().__init__(
            "replay_of", f"run '{run_id}' is {status}; {hint}", code="replay_source_not_completed"
        )


def check_reasoner(reasoner: str, replay_of: str | None) -> None:
    """`replay_of` goes with the replay reasoner, and only with it."""
    if reasoner == REPLAY and replay_of is None:
        raise DomainError(
            "replay_of",
            "the 'replay' reasoner needs 'replay_of': the id of a completed run (see GET /runs)",
            code="missing",
        )
    if reasoner != REPLAY and replay_of is not None:
        raise DomainError(
            "replay_of",
            f'\'replay_of\' only goes with "reasoner": "replay" '
            f"(this request's reasoner is '{reasoner}'); drop one of them",
            code="replay_of_without_replay",
        )


class ReplaySourceArchivedError(DomainError):
    """410: the run named by replay_of was archived; its record is the archive file."""

    status_code = 410

    def __init__(self, run_id: str, archive_file: str) -> None:
        super().__init__(
            "replay_of",
            f"run '{run_id}' was archived to '{archive_file}'; replay a run still stored",
            code="archived",
        )


def original_spec(*, session: Session, replay_of: str) -> RunSpec:
    """The spec of the completed run to replay. An unknown id is a 422 naming the body
    field (a 404 would suggest the URL is wrong); a run not completed is a 409."""
    run = repo.get_run(session=session, run_id=replay_of)
    if run is None and session.get(ArchivedRun, replay_of) is not None:
        gone = session.get(ArchivedRun, replay_of)
        assert gone is not None
        raise ReplaySourceArchivedError(replay_of, gone.archive_file)
    if run is None:
        raise DomainError(
            "replay_of",
            f"no run with id '{replay_of}' to replay; list runs with GET /runs?status=completed",
            code="unknown_run",
        )
    if run.status != RunStatus.COMPLETED:
        raise ReplaySourceNotFinishedError(replay_of, run.status)
    if run.revision_of is not None:
        # Its pins are rows it was created with, not replies a replay could reuse.
        raise DomainError(
            "replay_of",
            f"run '{replay_of}' is a revision (of run '{run.revision_of}'); replaying a "
            "revision is not supported yet: replay the run it revised, or revise that replay",
            code="revision_replay",
        )
    return RunSpec.from_json(run.request)


def _spec_field(request_field: str) -> str:
    return "instance_data" if request_field in _INSTANCE_FIELDS else request_field


def check_conflicts(original: RunSpec, replay_of: str, values: Mapping[str, Any]) -> None:
    """Each given value (by request field; None-valued NOT_FOR_REPLAY and review fields
    are absent) must be one a replay accepts: a copied field equal to the original's."""
    for name, value in values.items():
        if name == REVIEW:
            if value is None:
                continue
            raise DomainError(
                name,
                "a replay re-applies the original run's review settings and its recorded "
                "resolutions (it never waits for a supervisor), so it takes no 'review' of "
                "its own; omit it",
                code="not_for_replay",
            )
        if name in NOT_FOR_REPLAY:
            if value is None:
                continue
            raise DomainError(
                name,
                f"a replay calls no model and spends no tokens, so "
                f"'{name}' does not apply; omit it",
                code="not_for_replay",
            )
        spec_field = _spec_field(name)
        if spec_field not in COPIED:
            continue
        if value == getattr(original, spec_field):
            continue
        if spec_field == "instance_data":
            differs = f"describes another instance than run '{replay_of}'"
        else:
            differs = (
                f"differs from run '{replay_of}', whose {name} is {getattr(original, spec_field)!r}"
            )
        raise DomainError(
            name,
            f"{differs}; a replay copies the original's, so omit '{name}' or send the same value",
            code="replay_conflict",
        )


def replay_spec(
    *,
    sessions: sessionmaker[Session],
    reasoner: str,
    replay_of: str | None,
    sent: Mapping[str, Any],
) -> RunSpec:
    """The spec of a replay of run `replay_of`, given the fields a request sent explicitly
    (request field -> value, the instance as `instance_to_dict` of what it describes)."""
    check_reasoner(reasoner, replay_of)
    assert replay_of is not None  # check_reasoner: a replay names its run
    with sessions() as session:
        original = original_spec(session=session, replay_of=replay_of)
    check_conflicts(original, replay_of, sent)
    return dataclasses.replace(
        original,
        reasoner=REPLAY,
        replay_of=replay_of,
        model=None,
        temperature=None,
        token_budget=None,
    )


def validate_replay(*, sessions: sessionmaker[Session], spec: RunSpec) -> None:
    """Before a run is written: a replay names a completed run and copies its parameters."""
    check_reasoner(spec.reasoner, spec.replay_of)
    if spec.replay_of is None:
        return
    with sessions() as session:
        original = original_spec(session=session, replay_of=spec.replay_of)
    own = {name: getattr(spec, name) for name in (*COPIED, *NOT_FOR_REPLAY)}
    check_conflicts(original, spec.replay_of, own)


def recorded_replies(
    *, sessions: sessionmaker[Session], run_id: str
) -> dict[ReplyKey, RecordedReply]:
    """The replies run `run_id` recorded, by (task_index, attempt), as plain data."""
    with sessions() as session:
        rows = decision_repo.attempt_replies(session=session, run_id=run_id)
    return {
        (row.task_index, row.attempt): RecordedReply(
            text=row.reply_text,
            model=row.reply_model,
            input_tokens=row.input_tokens,
            output_tokens=row.output_tokens,
            extra=dict(row.reply_extra or {}),
        )
        for row in rows
    }
