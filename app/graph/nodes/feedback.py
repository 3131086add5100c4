"""Node 5, build_feedback: what failed, which rule, how to fix it."""

from __future__ import annotations

from typing import Any

from langgraph.runtime import Runtime

from app.domain.decision import DecisionContext
from app.domain.tradeoff import CLEAR_MARGIN, DECISIVE_GAP, NEGLIGIBLE_GAP
from app.graph.nodes.common import cancellable, current_attempt
from app.graph.nodes.validate import judge
from app.graph.reply_schema import allowed_labels
from app.graph.state import GraphContext, LTAAState
from app.graph.validation import CRITERION_TITLES, WEIGHTS, Validation
from app.reasoners.structured import ReplyFormat

_FIXES = {
    "explanation": "write 2-4 sentences that name your robot and cite its S and load against "
    "the alternatives",
    "success_accuracy": "state exactly the S of your chosen robot from the robot table",
    "tradeoff_analysis": "compare the best and the least-loaded robot by name, with their S, "
    "loads and the gap in points",
    "workload_awareness": "list every robot's load after adding this task to your robot only",
    "mode_compliance": f"apply the framework: gap > {DECISIVE_GAP:g} best, < {NEGLIGIBLE_GAP:g} "
    "least-loaded, otherwise compare the gap with the mode threshold",
    "phase_consistency": "name the current phase, and no other",
    "logical_consistency": "discuss the robot you chose and give its own success rate",
    "confidence_justification": f"High when the gap is {CLEAR_MARGIN:g}+ points from the "
    "deciding cut-off, Medium when closer, Low only against the rule",
}


def compose_feedback(
    verdict: Validation,
    dctx: DecisionContext,
    threshold: float,
    fmt: ReplyFormat = ReplyFormat.MARKDOWN,
) -> str:
    """First line: a one-line summary (it becomes the failure-log entry). Then one line per
    criterion that lost points, largest loss first."""
    labels = dctx.labels
    if verdict.hard_invalid is not None and fmt.structured:
        return (
            f"Hard invalid (Q=0): {verdict.hard_invalid}.\n"
            f"- Fix: reply with the one JSON object asked for, every field filled, "
            f"`decision` one of: {', '.join(allowed_labels(dctx))}"
            + ("; `team` one entry per unit" if dctx.team is not None else "")
            + "."
        )
    if verdict.hard_invalid is not None and dctx.team is not None:
        needs = ", ".join(f"{f} x{dctx.team.count(f)}" for f in dctx.team.features)
        return (
            f"Hard invalid (Q=0): {verdict.hard_invalid}.\n"
            f"- Fix: under **Team** give one line per unit ({needs}), `- <feature>: <robot> — "
            "<why>`, with distinct robots each listed for its unit above, then every section "
            "of the required format."
        )
    if verdict.hard_invalid is not None:
        allowed = ", ".join(labels[r] for r in dctx.feasible)
        return (
            f"Hard invalid (Q=0): {verdict.hard_invalid}.\n"
            f"- Fix: start with '**Decision**: <label>' naming one allowed robot ({allowed}), "
            "then give every section of the required format."
        )
    lost = sorted(
        ((WEIGHTS[k] * (1.0 - q), k) for k, q in verdict.scores.items() if q < 1.0), reverse=True
    )
    weakest = ", ".join(f"{CRITERION_TITLES[k]} {verdict.scores[k]:.2f}" for _, k in lost[:3])
    lines = [
        f"Q={verdict.quality:.2f} below the threshold {threshold:.2f}; weakest: "
        f"{weakest or 'none'}."
    ]
    for _, k in lost:
        note = verdict.notes.get(k, "incomplete")
        if k == "phase_consistency":
            fix = f"name the current phase ({dctx.phase.value}), and no other"
        else:
            fix = _FIXES[k]
        lines.append(
            f"- {CRITERION_TITLES[k]} (weight {WEIGHTS[k]:.2f}, scored "
            f"{verdict.scores[k]:.2f}): {note}. Fix: {fix}."
        )
    return "\n".join(lines)


@cancellable
def build_feedback(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
    ctx = runtime.context
    record, dctx = current_attempt(ctx, state)
    verdict = ctx.verdicts.recall(state["task_index"], state["attempt"])
    if verdict is None:  # resumed after validate: its in-memory verdict did not survive
        verdict = judge(record, dctx, ctx.quality_threshold)
    record.feedback = compose_feedback(
        verdict, dctx, ctx.quality_threshold, ctx.model_use.reply_format
    )
    ctx.recorder.save_attempt(record)
    return {}
