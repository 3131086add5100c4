"""The LTAA graph's team decisions (docs/allocation.md#teams): the team prompt, the tolerant
**Team** parser, each hard rule of team validation, the per-member criteria, the rules
reasoner's team rule and the fallback team, and the `ltaa` solver on small team instances
against an exhaustive search written in tests/domain/test_teams.py."""

from __future__ import annotations

import itertools
import random

import pytest

from app.domain.decision import DecisionContext
from app.domain.metrics import expected_success
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.graph.context import decision_context
from app.graph.parsing import parse_response
from app.graph.prompts import TARGET_USER_PROMPT_CHARS, prompt_for, prompt_size
from app.graph.state import task_view
from app.graph.validation import validate_text
from app.reasoners.rules import choose_team, compose_answer
from app.reasoners.scope import is_contested
from app.solvers.registry import get_solver
from tests.domain.test_teams import _choices, _covers, exhaustive
from tests.fakes.scripted_reasoner import GARBAGE, ScriptedReasoner
from tests.support.ltaa_support import run

CRANE, ARM, LIFTER, SWEEPER = 0, 1, 2, 3
ROBOTS = (
    Robot("crane", {"heavy": 0.9, "careful": 0.2}, label="Crane", skills=("heavy",)),
    Robot("arm", {"heavy": 0.3, "careful": 0.95}, label="Arm"),
    Robot("lifter", {"heavy": 0.8, "careful": 0.4}, label="Lifter"),
    Robot("sweeper", {"heavy": 0.1, "careful": 0.7}, label="Sweeper", skills=("careful",)),
)
TASKS = (
    Task("beam", "Lift beam", ("heavy",), team={"heavy": 2}),
    Task("panel", "Fix panel", ("heavy", "careful"), team={"heavy": 1, "careful": 1}),
    Task("sweep", "Sweep", ("careful",)),
    Task("carry", "Carry", ("heavy",)),
)
PROBLEM = Problem.build(Instance(TASKS, ROBOTS), Mode.SUCCESS_FOCUSED)


def ctx_at(
    problem: Problem, t: int, loads: list[int], guided: list[int] | None = None
) -> DecisionContext:
    view = task_view(problem, t, loads, None, guided_team=guided)
    state = {"task_index": t, "loads": loads, "view": view, "attempt": 1}
    return decision_context(problem, state)


CTX = ctx_at(PROBLEM, 1, [1, 0, 1, 0])  # the panel, after crane and lifter carried the beam


def with_team(lines: list[str], ctx: DecisionContext = CTX) -> str:
    """The rules answer with its **Team** block replaced by `lines`."""
    out, skipping = [], False
    for line in compose_answer(ctx).splitlines():
        if line.startswith("**Team**"):
            out.append("**Team**:")
            out.extend(lines)
            skipping = True
        elif line.startswith("**"):
            skipping = False
            out.append(line)
        elif not skipping:
            out.append(line)
    return "\n".join(out)


def test_the_prompt_lists_each_unit_with_its_robots_and_asks_for_the_whole_team() -> None:
    text = prompt_for(CTX)
    assert "Team task: heavy x1, careful x1; 2 distinct robots at once" in text
    # Per unit, the robots that may cover it with their rate for its feature, best first;
    # the sweeper's skills keep it off the heavy unit, the crane's off the careful one.
    assert "- heavy x1: Crane 90.0%, Lifter 80.0%, Arm 30.0%" in text
    assert "- careful x1: Arm 95.0%, Sweeper 70.0%, Lifter 40.0%" in text
    assert "- Crane [crane]: load 1 (dev -0.5)" in text
    assert "- best: heavy: Crane; careful: Arm (S 92.5%, loads 1)" in text
    assert "**Team**:" in text and "one line per unit" in text
    size = prompt_size(CTX)
    assert size["user_chars"] == len(text) < TARGET_USER_PROMPT_CHARS
    for tier in (1, 2, 3):
        retry = prompt_for(CTX, tier, feedback="- fix it", quality=0.2)
        assert "- heavy x1:" in retry and "**Team**" in retry


@pytest.mark.parametrize(
    "block",
    [
        "- heavy: Crane — strongest lifter at 90%.\n- careful: Arm — most careful at 95%.",
        "heavy -> crane: strongest lifter at 90%\ncareful = ARM (most careful at 95%)",
        "1. careful: Arm - most careful, 95%\n2. heavy: Crane - lifts at 90%",
        "* Crane covers heavy because it lifts at 90%\n* Arm covers careful because 95%",
    ],
)
def test_the_team_block_is_read_tolerantly(block: str) -> None:
    parsed = parse_response(
        f"**Decision**: Crane\n**Team**:\n{block}\n**Expected Success**: 92.5%",
        CTX.robot_names,
        CTX.labels,
        CTX.team.features if CTX.team else (),
    )
    assert sorted((line["feature"], line["robot"]) for line in parsed.team) == [
        ("careful", ARM),
        ("heavy", CRANE),
    ]
    assert all(line["reason"] for line in parsed.team)
    assert parsed.robot == CRANE and parsed.expected_success == pytest.approx(0.925)


def test_the_rules_team_is_accepted_and_says_why_for_each_member() -> None:
    verdict = validate_text(compose_answer(CTX), CTX)
    assert verdict.hard_invalid is None and verdict.accepted, verdict.notes
    assert verdict.team == (CRANE, ARM) and verdict.robot == CRANE
    assert verdict.quality == 1.0, verdict.notes
    # The team's true success is the mean over units of the member's rate.
    assert CTX.team is not None and CTX.team.success((CRANE, ARM)) == pytest.approx(0.925)


HARD = [
    ("no_team_block", None, "no **Team** block"),
    ("uncovered_unit", ["- heavy: Crane — lifts at 90%."], "1 unit(s) of careful not covered"),
    (
        "repeated_member",
        ["- heavy: Lifter — lifts at 80%.", "- careful: Lifter — careful at 40%."],
        "Lifter covers two units",
    ),
    (
        "ineligible_member",
        ["- heavy: Sweeper — lifts at 10%.", "- careful: Arm — careful at 95%."],
        "Sweeper cannot cover heavy (its skills rule it out)",
    ),
    (
        "unknown_robot",
        ["- heavy: Bulldozer — lifts a lot.", "- careful: Arm — careful at 95%."],
        "unknown robot 'Bulldozer' for heavy",
    ),
    (
        "too_many_for_a_feature",
        ["- heavy: Crane — 90%.", "- heavy: Lifter — 80%.", "- careful: Arm — 95%."],
        "2 robots named for heavy",
    ),
]


@pytest.mark.parametrize(("lines", "words"), [c[1:] for c in HARD], ids=[c[0] for c in HARD])
def test_each_hard_rule_makes_the_team_invalid(lines: list[str] | None, words: str) -> None:
    if lines is None:
        text = "\n".join(x for x in compose_answer(CTX).splitlines() if x.startswith("**Decision"))
    else:
        text = with_team(lines)
    verdict = validate_text(text, CTX)
    assert verdict.quality == 0.0 and not verdict.accepted
    assert verdict.hard_invalid is not None and words in verdict.hard_invalid, verdict.hard_invalid


def test_a_team_that_makes_the_cap_infeasible_is_hard_invalid() -> None:
    # max_deviation 0: every robot ends with exactly one unit, and only c may take the careful
    # task after the beam; so a beam team with c on it leaves that task no robot (the max-flow
    # completion check over the units left), though c lifts best.
    robots = (
        Robot("a", {"heavy": 0.9, "careful": 0.1}, skills=("heavy",)),
        Robot("b", {"heavy": 0.5, "careful": 0.1}, skills=("heavy",)),
        Robot("c", {"heavy": 0.95, "careful": 0.9}),
    )
    tasks = (Task("beam", "Beam", ("heavy",), team={"heavy": 2}), Task("fix", "Fix", ("careful",)))
    problem = Problem.build(Instance(tasks, robots), Mode.SUCCESS_FOCUSED, 0)
    ctx = ctx_at(problem, 0, [0, 0, 0])
    assert ctx.team is not None and ctx.team.best == (0, 1)  # not the better-rated (0, 2)
    text = with_team(["- heavy: a — lifts at 90%.", "- heavy: c — lifts at 95%."], ctx)
    verdict = validate_text(text, ctx)
    assert verdict.quality == 0.0 and "workload cap infeasible" in (verdict.hard_invalid or "")
    assert validate_text(compose_answer(ctx), ctx).accepted


def test_each_members_sentence_counts_and_success_is_the_teams() -> None:
    full = validate_text(compose_answer(CTX), CTX)
    bare = validate_text(with_team(["- heavy: Crane", "- careful: Arm"]), CTX)
    assert bare.hard_invalid is None
    assert bare.scores["explanation"] == pytest.approx(full.scores["explanation"] - 0.5)
    assert "gives no reason" in bare.notes["explanation"]
    wrong = compose_answer(CTX).replace(
        "**Expected Success**: 92.5%", "**Expected Success**: 90.0%"
    )
    assert validate_text(wrong, CTX).scores["success_accuracy"] < 1.0
    # Another valid team is accepted as valid but loses mode compliance to the rule's team.
    other = validate_text(
        with_team(["- heavy: Lifter — lifts at 80%.", "- careful: Arm — careful at 95%."]), CTX
    )
    assert other.hard_invalid is None and other.team == (LIFTER, ARM)
    assert other.scores["mode_compliance"] < 1.0


def test_the_team_rule_weighs_the_best_team_against_the_least_loaded() -> None:
    # Crane and lifter carry two tasks each; arm and sweeper none. The least-loaded team
    # (arm on heavy 30%, sweeper on careful 70%: S 50%) is 42.5 points below the best: best wins.
    ctx = ctx_at(PROBLEM, 1, [2, 0, 2, 0])
    members, rule = choose_team(ctx)
    assert rule.fewest == (ARM, SWEEPER) and rule.best == (CRANE, ARM)
    assert members == rule.best and rule.rule.gap == pytest.approx(42.5)
    # Guided, the rules reasoner follows the optimizer's team when the cap allows it.
    guided = ctx_at(PROBLEM, 1, [2, 0, 2, 0], guided=[LIFTER, SWEEPER])
    assert choose_team(guided)[0] == (LIFTER, SWEEPER)


def test_the_fallback_is_the_rules_team_and_loads_count_every_member() -> None:
    rec, _ = run(PROBLEM, ScriptedReasoner(then=GARBAGE), max_retries=1)
    decisions = rec.decisions()
    assert [d.fallback for d in decisions] == [True] * 4
    assert [len(d.team or []) for d in decisions] == [2, 2, 0, 0]
    assert decisions[0].team == [
        {"robot": "crane", "feature": "heavy"},
        {"robot": "lifter", "feature": "heavy"},
    ]
    for d in decisions:
        members = [m["robot"] for m in d.team] if d.team else [d.robot_name]
        added = [a - b for a, b in zip(d.loads_after, d.loads_before, strict=True)]
        assert sum(added) == len(members)
        assert all(added[[r.name for r in ROBOTS].index(m)] == 1 for m in members)


def _random_instance(rng: random.Random) -> Instance:
    robots = tuple(
        Robot(
            f"r{k}",
            {"heavy": rng.choice([0.2, 0.5, 0.9]), "careful": rng.choice([0.3, 0.6, 0.95])},
            skills=rng.choice([None, ("heavy",), ("careful",), ("heavy", "careful")]),
        )
        for k in range(4)
    )
    teams = [{"heavy": 2}, {"heavy": 1, "careful": 1}, {"careful": 2}]
    tasks = []
    for k in range(5):
        if rng.random() < 0.5:
            team = rng.choice(teams)
            tasks.append(Task(f"t{k}", f"t{k}", tuple(team), team=team))
        else:
            tasks.append(Task(f"t{k}", f"t{k}", (rng.choice(["heavy", "careful"]),)))
    return Instance(tuple(tasks), robots)


@pytest.mark.parametrize("seed", range(8))
def test_the_ltaa_solver_forms_valid_teams_and_guided_reaches_the_optimum(seed: int) -> None:
    rng = random.Random(seed)
    for _ in range(50):
        try:
            instance = _random_instance(rng)
            problem = Problem.build(instance, Mode.BALANCED)
        except Exception:
            continue
        best = exhaustive(instance, problem.cap.max_deviation)
        if best is not None:
            break
    assert best is not None
    for guidance in (None, "optimizer"):
        solution = get_solver("ltaa").solve(problem, options={"guidance": guidance})
        loads = [0] * 4
        for t, task in enumerate(instance.tasks):
            members = solution.teams.get(t, (solution.assignment[t],))
            assert len(set(members)) == len(members)
            if task.team:
                units = [f for f, c in task.team.items() for _ in range(c)]
                assert len(members) == len(units)
                assert all(
                    _covers(instance.robots[r], f) for r, f in zip(members, units, strict=True)
                )
            for r in members:
                loads[r] += 1
        assert problem.cap.respected_by(loads), loads
        got = expected_success(instance, solution.assignment, solution.teams)
        if guidance:
            # The exhaustive optimum (a sum of success over the tasks, in exact arithmetic).
            assert got * instance.n_tasks == pytest.approx(float(best[0]), abs=1e-9)
            assert solution.details["regret"] == pytest.approx(0.0, abs=1e-9)


def _brute_completes(instance: Instance, problem: Problem, after: int, loads: list[int]) -> bool:
    """Some staffing of the tasks after `after` (one robot, or distinct members per unit, each
    eligible) ends every load within the cap: tried exhaustively."""
    lo, hi = problem.cap.lower, problem.cap.upper
    options = [_choices(instance, t) for t in range(after + 1, instance.n_tasks)]
    return any(
        all(lo <= x <= hi for x in _added(loads, plan)) for plan in itertools.product(*options)
    )


def _added(loads: list[int], plan: tuple[tuple[int, ...], ...]) -> list[int]:
    out = list(loads)
    for members in plan:
        for r in members:
            out[r] += 1
    return out


@pytest.mark.parametrize("seed", range(6))
def test_the_unit_completion_check_agrees_with_exhaustive_search(seed: int) -> None:
    # Identical team tasks share nodes in the flow (Koenig's theorem says that is exact):
    # draws with repeated teams check it against every staffing.
    rng = random.Random(100 + seed)
    checked = 0
    while checked < 12:
        try:
            instance = _random_instance(rng)
            problem = Problem.build(instance, Mode.BALANCED, rng.choice([0.5, 1.0, 2.0]))
        except Exception:
            continue
        after = rng.randrange(instance.n_tasks - 1)
        loads = [rng.randrange(0, 4) for _ in range(4)]
        expected = _brute_completes(instance, problem, after, loads)
        assert problem.completes_after(after, loads) == expected, (seed, after, loads)
        checked += 1


def test_llm_scope_judges_a_team_decision_on_its_two_candidate_teams() -> None:
    # A 42.5-point gap is far from every threshold: clear-cut, the rules answer it.
    assert not is_contested(ctx_at(PROBLEM, 1, [2, 0, 2, 0]))
    # Guidance naming another team than the rule's makes it contested.
    assert is_contested(ctx_at(PROBLEM, 1, [2, 0, 2, 0], guided=[LIFTER, SWEEPER]))
