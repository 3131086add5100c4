"""Node 7, finalize: the decision (accepted answer, or the rules fallback) and its record."""

from __future__ import annotations

from typing import Any

from langgraph.runtime import Runtime

from app.domain.decision import DecisionContext
from app.graph.context import decision_context
from app.graph.nodes.common import cancellable, timing
from app.graph.nodes.validate import judge
from app.graph.recorder import AttemptRecord
from app.graph.review import gate
from app.graph.state import GraphContext, LTAAState
from app.graph.timing import best_in_time, fallback_answer, time_record
from app.graph.validation import validate_text
from app.reasoners.rules import choose, choose_team, compose_answer, compose_team_answer

_TIMED_TEAM_FALLBACK = (
    "Fallback after the attempts failed: the best-success team that keeps the workload cap "
    "and whose members are free in time"
)


def _team_success(dctx: DecisionContext, team: tuple[int, ...]) -> float:
    assert dctx.team is not None
    return dctx.team.success(team)


def failure_line(record: AttemptRecord, threshold: float) -> str:
    if record.feedback:
        why = record.feedback.splitlines()[0]
    elif record.hard_invalid:
        why = f"Hard invalid (Q=0): {record.hard_invalid}."
    else:
        why = f"Q={(record.quality or 0.0):.2f} below the threshold {threshold:.2f}."
    return f"attempt {record.attempt} (tier {record.tier}): {why}"


@cancellable
def finalize(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
    ctx = runtime.context
    rec = ctx.recorder
    t, a = state["task_index"], state["attempt"]
    dctx = decision_context(ctx.problem, state, **timing(ctx, state))
    records = [r for k in range(1, a + 1) if (r := rec.attempt(t, k)) is not None]
    failures = [failure_line(r, ctx.quality_threshold) for r in records if not r.accepted]
    # The answer's text stays in the recorder when it is there already (the accepted
    # attempt): copying it into state would put it into several checkpoints per task.
    text: dict[str, Any]
    chosen = state.get("robot")
    team: tuple[int, ...] | None = None
    if state.get("accepted") and chosen is not None:
        robot, fallback = chosen, False
        accepted = next(r for r in reversed(records) if r.accepted)
        quality = accepted.quality or 0.0
        confidence = (accepted.parsed or {}).get("confidence")
        text = {"text_attempt": accepted.attempt}
        if dctx.team is not None:
            # The members from the accepted reply, judged again (pure): never from state.
            team = judge(accepted, dctx, ctx.quality_threshold).team
    elif dctx.team is not None:
        # docs/allocation.md#teams: the rules reasoner's team, which keeps the cap satisfiable;
        # in time, the best-success team that also is free in time (as for one robot).
        answer = compose_answer(dctx)
        if dctx.team.timing is not None and dctx.team.best is not None:
            team = dctx.team.best
            answer = compose_team_answer(dctx, team, _TIMED_TEAM_FALLBACK)
        else:
            team = choose_team(dctx)[0]
        robot = team[0]
        verdict = validate_text(answer, dctx, ctx.quality_threshold)
        fallback, quality = True, verdict.quality
        confidence = verdict.parsed.confidence
        text = {"reasoning": verdict.parsed.reasoning, "tradeoff": verdict.parsed.tradeoff}
    elif dctx.timing:
        # docs/schedules.md#validation-in-time: in time, the fallback takes the allowed robot with
        # the best success.
        robot = best_in_time(dctx)
        verdict = validate_text(fallback_answer(dctx, robot), dctx, ctx.quality_threshold)
        fallback, quality = True, verdict.quality
        confidence = verdict.parsed.confidence
        text = {"reasoning": verdict.parsed.reasoning, "tradeoff": verdict.parsed.tradeoff}
    else:
        # The conservative fallback: the rules reasoner's answer, validated like any other.
        # The robot comes from the rule itself, never from re-parsing its text.
        robot = choose(dctx)[0]
        verdict = validate_text(compose_answer(dctx), dctx, ctx.quality_threshold)
        fallback, quality = True, verdict.quality
        confidence = verdict.parsed.confidence
        text = {"reasoning": verdict.parsed.reasoning, "tradeoff": verdict.parsed.tradeoff}
    decision = {
        **text,
        "expected_success": dctx.success[robot] if team is None else _team_success(dctx, team),
        "confidence": confidence or "",
        "quality": quality,
        "fallback": fallback,
        "attempts": a,
        "failure_log": failures,
        "phase": state["view"]["phase"],
        "loads_before": list(state["loads"]),
        "balance_before": state["view"]["balance"],
    }
    if team is not None:
        decision["team"] = list(team)
    if ctx.review is not None:
        # Last, and after nothing but reads: a resumed graph re-runs this node from its top.
        def texts() -> tuple[str, str]:
            if "text_attempt" in text:
                parsed = accepted.parsed or {}
                return str(parsed.get("reasoning") or ""), str(parsed.get("tradeoff") or "")
            return str(text["reasoning"] or ""), str(text["tradeoff"] or "")

        task = ctx.problem.instance.tasks[t]
        reviewed = gate(
            ctx.review,
            dctx,
            task_id=task.id,  # as the request gave it: GET /reviews shows it so
            robot=robot,
            decision=decision,
            text=texts,
            team=team,
        )
        if reviewed is not None:
            # Loads, balance, regret and every later decision follow the reviewed robot (a
            # team decision: the reviewed team, docs/reviews.md#reviews-of-team-decisions).
            robot, team = reviewed.robot, reviewed.team
            decision["expected_success"] = (
                dctx.success[robot] if team is None else _team_success(dctx, team)
            )
            decision["review"] = reviewed.review
            if team is not None:
                decision["team"] = list(team)
    if dctx.timing:
        seq = ctx.timed.at(ctx.problem, rec, t).decided
        decision["time"] = time_record(dctx, robot, seq, team)
    return {"robot": robot, "fallback": fallback, "decision": decision}
