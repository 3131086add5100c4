"""Prompts for the reason node: one constant system prompt, a compact dynamic user prompt,
and three genuinely different retry tiers.

Tier 0 carries only facts, guidance and the format. Tier 1 adds the validator's specific
feedback. Tier 2 replaces brevity with a full scoring guide and a worked example. Tier 3
drops explanation in favour of a step-by-step fill-in template.
"""

from __future__ import annotations

import math

from app.domain.decision import DecisionContext, percent
from app.domain.modes import MODE_DESCRIPTIONS, tradeoff_threshold
from app.domain.phases import Phase
from app.domain.tradeoff import CLEAR_MARGIN, DECISIVE_GAP, NEGLIGIBLE_GAP
from app.graph import structured_prompts as structured
from app.graph.team_prompts import (
    TEAM_FORMAT,
    team_facts_text,
    team_framework,
    team_steering,
    team_step_template,
)
from app.graph.validation import CRITERION_TITLES, WEIGHTS
from app.reasoners.structured import ReplyFormat

MARKDOWN = ReplyFormat.MARKDOWN

TARGET_USER_PROMPT_CHARS = 2_500

SYSTEM_PROMPT = (
    "You are the reasoning step of LTAA, a construction-site task allocator. Each message "
    "describes one task and a fleet of robots. Choose exactly one robot, weighing task success "
    "against workload balance as the operational mode and workflow phase direct, and never a "
    "robot the workload cap forbids. For a team task, choose the whole team: one distinct robot "
    "per unit, each with its reason. Use only the numbers given; do not invent data. Reply in "
    "the required markdown format and nothing else."
)


def system_prompt(fmt: ReplyFormat = MARKDOWN) -> str:
    """The system prompt of a run asking in `fmt`: the same but for how to reply."""
    if not fmt.structured:
        return SYSTEM_PROMPT
    return SYSTEM_PROMPT.replace(
        "Reply in the required markdown format and nothing else.", structured.SYSTEM_SUFFIX
    )


_PHASE_GUIDANCE = {
    Phase.EARLY: "early: secure high success while loads are still even",
    Phase.MIDDLE: "middle: weigh success and balance; start closing load gaps",
    Phase.LATE: "late: balance is urgent; correct deviations before the queue ends",
}

_FORMAT = """Reply in exactly this format:
**Decision**: <robot label>
**Expected Success**: <S of the chosen robot, e.g. 70.0%>
**Reasoning**: <2-4 sentences citing S values, loads and the phase>
**Workload After Assignment**: <Label: count, for every robot>
**Confidence Level**: <High|Medium|Low>
**Trade-Off Summary**: <best vs least-loaded robot, gap in points, rule applied>
**Robot Analysis**: <optional: one line per robot>"""


def _facts(ctx: DecisionContext) -> str:
    if ctx.team is not None:  # docs/allocation.md#teams: per unit, who may cover it
        return team_facts_text(ctx)
    labels = ctx.labels
    allocated = sum(ctx.loads)
    task_type = f" ({ctx.task_type})" if ctx.task_type else ""
    notes = ctx.rate_notes or ("",) * len(labels)
    rows = [
        f"- {labels[r]} [{ctx.robot_names[r]}]: S {percent(ctx.success[r])}"
        + (f" ({notes[r]})" if notes[r] else "")
        + f", load {ctx.loads[r]} (dev {ctx.loads[r] - ctx.target:+.1f})"
        + ("" if r in ctx.feasible else ", NOT allowed")
        + (", cannot take this task" if ctx.eligible and not ctx.eligible[r] else "")
        for r in range(len(labels))
    ]
    if ctx.load_bounds is None:
        cap = "no workload cap"
    else:
        cap = f"cap: final loads in [{ctx.load_bounds[0]}, {ctx.load_bounds[1]}]"
    number = ctx.task_index if ctx.allocated is None else ctx.allocated
    return "\n".join(
        [
            f"Task {number + 1}/{ctx.total_tasks}: {ctx.task_name}{task_type}; "
            f"features: {', '.join(ctx.features)}",
            "Robots (S = mean success over the task's features; load = tasks so far):",
            *rows,
            *(
                ["Learned rates are posterior means from this site's reports."]
                if any(notes)
                else []
            ),
            f"Target load W = {ctx.target:.1f}; allocated {allocated}/{ctx.total_tasks}; {cap}.",
            *_time_facts(ctx),
        ]
    )


def _minutes(x: float) -> str:
    return f"{x:g}"


def _time_facts(ctx: DecisionContext) -> list[str]:
    """docs/schedules.md#the-prompt-in-time: per robot, when it is next free, its travel to the
    task's zone, the start and end it would give and the slack to the deadline (nothing on an
    untimed instance)."""
    if not ctx.timing:
        return []
    where = f"zone {ctx.zone}, " if ctx.zone is not None else ""
    deadline = "no deadline" if ctx.deadline is None else f"deadline {_minutes(ctx.deadline)}"
    rows = []
    for o in ctx.timing:
        head = f"- {ctx.labels[o.robot]}: free {_minutes(o.free)}, travel {_minutes(o.travel)}"
        if o.end == math.inf:
            rows.append(f"{head}, {o.why_not}")
            continue
        slack = "" if o.slack == math.inf else f", slack {_minutes(o.slack)}"
        rows.append(
            f"{head}, start {_minutes(o.start)}, end {_minutes(o.end)}{slack}"
            + ("" if o.allowed else f", NOT allowed: {o.why_not}")
        )
    return [
        f"Time (minutes from the plan's start; {where}release {_minutes(ctx.release)}, "
        f"{deadline}):",
        *rows,
        *(["Links (the starts above honour them): " + "; ".join(ctx.links)] if ctx.links else []),
        "A robot that misses the deadline or ends after its shift is not allowed. In the "
        "Trade-Off Summary, say how many minutes later your robot ends than the earliest end.",
    ]


def _guidance(ctx: DecisionContext) -> str:
    return "\n".join(_situation(ctx) + _framework(ctx) + _steering(ctx))


def _situation(ctx: DecisionContext) -> list[str]:
    """Where the run stands: the phase and its progress, the mode and its weights now."""
    done = ctx.task_index if ctx.allocated is None else ctx.allocated
    progress = done / ctx.total_tasks if ctx.total_tasks else 1.0
    return [
        f"Phase: {ctx.phase.value} (progress {progress:.0%}); {_PHASE_GUIDANCE[ctx.phase]}.",
        f"Mode: {ctx.mode.value}, {MODE_DESCRIPTIONS[ctx.mode]}; weights success:balance "
        f"{ctx.weights} now.",
    ]


def _framework(ctx: DecisionContext) -> list[str]:
    """The trade-off rule and the confidence it implies: the same for every decision of a
    mode and phase."""
    if ctx.team is not None:
        return team_framework(ctx)
    threshold = tradeoff_threshold(ctx.mode, ctx.phase)
    return [
        "Decision framework, among allowed robots: best = highest S, fewest = lowest load, "
        f"gap = S(best) - S(fewest) in points. Gap > {DECISIVE_GAP:g}: best. Gap < "
        f"{NEGLIGIBLE_GAP:g}: fewest. Otherwise best if gap > {threshold:g} (this mode and "
        "phase), else fewest.",
        f"Confidence: High if the gap is {CLEAR_MARGIN:g}+ points from the deciding cut-off, "
        "Medium if closer, Low if you depart from the rule.",
    ]


def _steering(ctx: DecisionContext) -> list[str]:
    return team_steering(ctx) if ctx.team is not None else _optimizer_guidance(ctx)


def _optimizer_guidance(ctx: DecisionContext) -> list[str]:
    """The optimizer's choice, when the run asked for it (every tier carries it)."""
    if ctx.guided_robot is None:
        return []
    lines = [
        f"Optimizer guidance: {ctx.labels[ctx.guided_robot]} lies on the optimal "
        "completion of the queue; follow it, or explain in the reasoning why you depart."
    ]
    if ctx.guided_costs is not None:
        costs = ", ".join(
            f"{label} {'not allowed' if c is None else f'{c:.1f}'}"
            for label, c in zip(ctx.labels, ctx.guided_costs, strict=True)
        )
        lines.append(f"Success points each choice gives away over the queue: {costs}.")
    return lines


def _format(ctx: DecisionContext) -> str:
    return TEAM_FORMAT if ctx.team is not None else _FORMAT


def user_prompt(ctx: DecisionContext, fmt: ReplyFormat = MARKDOWN) -> str:
    """Tier 0: the first try."""
    if fmt.structured:
        return _structured(ctx, 0)
    return "\n\n".join([_facts(ctx), _guidance(ctx), _format(ctx)])


def _structured(ctx: DecisionContext, tier: int, feedback: str = "") -> str:
    """A structured run's prompt (docs/reasoners.md#structured-replies): the same parts as the
    markdown tiers, ordered for the servers' prompt caches (llama.cpp, vLLM and OpenAI reuse
    the longest prefix already computed): what is the same for every decision of a run
    first (the reply object, the rule of its mode and phase; at tier 2 the scoring guide and
    the example), then the task's facts, then the feedback on the last answer (and at tier 3
    the steps of the rule with the task's numbers)."""
    stable = [structured.json_format(ctx), "\n".join(_framework(ctx))]
    allowed = ", ".join(structured.allowed_labels(ctx))
    task = "\n".join([_facts(ctx), *_situation(ctx), f"Allowed now: {allowed}.", *_steering(ctx)])
    if tier == 0:
        return "\n\n".join([*stable, task])
    if tier <= 1:
        return "\n\n".join([*stable, task, feedback, "Answer again, fixing every problem listed."])
    if tier == 2:
        example = [] if ctx.team is not None else [structured.WORKED_EXAMPLE]
        return "\n\n".join([*stable, _criteria_guide(), *example, task, feedback])
    steps = (
        structured.team_step_template(ctx)
        if ctx.team is not None
        else (structured.step_template(ctx))
    )
    return "\n\n".join([*stable, task, feedback, steps])


def _feedback_block(feedback: str, quality: float | None, threshold: float) -> str:
    score = f"scored Q={quality:.2f}, needed {threshold:.2f}" if quality is not None else "failed"
    return f"Your previous answer {score}. Problems:\n{feedback.strip()}"


def _criteria_guide() -> str:
    lines = [f"- {CRITERION_TITLES[k]} ({w:.2f})" for k, w in WEIGHTS.items()]
    return (
        "How answers are scored (weights):\n" + "\n".join(lines) + "\n"
        "Expected Success must equal S of your robot; workload counts must add your task to "
        "its current load; name the current phase; the Trade-Off Summary must compare the "
        "best and least-loaded robots with the gap in points."
    )


_WORKED_EXAMPLE = """Worked example (different data): robots A (S 90%, load 5), B (S 70%, \
load 3), C (S 60%, load 4); middle phase, threshold 13. best = A, fewest = B, gap = 20 points: \
not > 25, not < 5, and 20 > 13, so choose A; 20 is 7 points from 13, so confidence High.
**Decision**: A
**Expected Success**: 90.0%
**Reasoning**: A has the highest success at 90.0% against 70.0% for B, the least-loaded robot \
with 3 tasks. The gap of 20 points exceeds the middle-phase threshold of 13, so success wins \
over balance.
**Workload After Assignment**: A: 6, B: 3, C: 4
**Confidence Level**: High
**Trade-Off Summary**: best A 90.0% vs least-loaded B 70.0% (3 tasks): gap 20 > 13 points, \
so A takes the task."""


def retry_prompt(
    ctx: DecisionContext,
    tier: int,
    feedback: str,
    quality: float | None,
    threshold: float,
    fmt: ReplyFormat = MARKDOWN,
) -> str:
    """Tiers 1-3; a tier above 3 uses tier 3."""
    fb = _feedback_block(feedback, quality, threshold)
    if fmt.structured:
        return _structured(ctx, min(tier, 3), fb)
    if tier <= 1:
        return "\n\n".join(
            [user_prompt(ctx, fmt), fb, "Answer again, fixing every problem listed."]
        )
    if tier == 2:
        example = [] if ctx.team is not None else [_WORKED_EXAMPLE]
        return "\n\n".join(
            [_facts(ctx), _guidance(ctx), fb, _criteria_guide(), *example, _format(ctx)]
        )
    if ctx.team is not None:
        template = structured.team_step_template(ctx) if fmt.structured else team_step_template(ctx)
        return "\n\n".join([_facts(ctx), _guidance(ctx), fb, template])
    # The step template replaces the framework text, but not the optimizer's choice.
    guidance = _optimizer_guidance(ctx)
    return "\n\n".join(
        [_facts(ctx), *(["\n".join(guidance)] if guidance else []), fb, _step_template(ctx)]
    )


def _step_template(ctx: DecisionContext) -> str:
    labels = ctx.labels
    allowed = ", ".join(labels[r] for r in ctx.feasible)
    threshold = tradeoff_threshold(ctx.mode, ctx.phase)
    counts = ", ".join(
        f"{labels[r]}: <{ctx.loads[r]} or {ctx.loads[r] + 1}>" for r in range(len(labels))
    )
    return f"""Work through these steps, then fill in the template. Replace every <...>.
1. Allowed robots: {allowed}.
2. best = the allowed robot with the highest S; fewest = the allowed robot with the lowest load.
3. gap = S(best) - S(fewest) in points.
4. If gap > {DECISIVE_GAP:g} choose best; if gap < {NEGLIGIBLE_GAP:g} choose fewest; otherwise \
choose best if gap > {threshold:g}, else fewest.
5. Workload after: add 1 to the chosen robot only.
6. Confidence: High if the gap is {CLEAR_MARGIN:g}+ points from the cut-off used in step 4, else \
Medium.

**Decision**: <robot from step 4>
**Expected Success**: <its S from the table>%
**Reasoning**: <robot> has S <S>% versus <other robot> at <S>%. The gap is <gap> points, so \
rule <step 4 clause> applies in the {ctx.phase.value} phase of {ctx.mode.value} mode.
**Workload After Assignment**: {counts}
**Confidence Level**: <High|Medium>
**Trade-Off Summary**: best <best> <S>% vs least-loaded <fewest> (<load> tasks): gap <gap> \
points, so <robot> takes the task."""


def prompt_for(
    ctx: DecisionContext,
    tier: int = 0,
    feedback: str = "",
    quality: float | None = None,
    threshold: float = 0.6,
    fmt: ReplyFormat = MARKDOWN,
) -> str:
    if tier == 0:
        return user_prompt(ctx, fmt)
    return retry_prompt(ctx, tier, feedback, quality, threshold, fmt)


def prompt_size(ctx: DecisionContext, tier: int = 0, fmt: ReplyFormat = MARKDOWN) -> dict[str, int]:
    """Characters in the system and user prompt (feedback-free for retry tiers)."""
    user = prompt_for(ctx, tier, feedback="-", quality=0.0, fmt=fmt)
    system = system_prompt(fmt)
    return {
        "system_chars": len(system),
        "user_chars": len(user),
        "total_chars": len(system) + len(user),
    }
