"""The LTAA graph forms teams in time (docs/allocation.md#teams, docs/schedules.md#runs-in-time):
its time lines place a team task in every member's lane, starting when the last member can
begin; "members free in time" is a hard rule of validation; the fallback takes the
best-success team that keeps the cap and fits in time; the loopback fakes of both SDKs
answer timed team decisions as the rules reasoner does."""

from __future__ import annotations

import functools
import random

import pytest

from app.domain.catalog import timed_scenario
from app.domain.decision import DecisionContext
from app.domain.links import Link
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.progress import TimedProgress
from app.graph.context import decision_context
from app.graph.prompts import TARGET_USER_PROMPT_CHARS, user_prompt
from app.graph.recorder import DecisionRecord
from app.graph.state import task_view
from app.graph.validation import validate_text
from app.reasoners.anthropic import AnthropicReasoner
from app.reasoners.openai import OpenAIReasoner
from app.reasoners.rules import RulesReasoner, compose_answer
from app.solvers.registry import get_solver
from app.solvers.timed_guidance import GuidancePlan, plan_guidance
from tests.fakes.fake_chat_completions_api import FakeChatCompletionsAPI
from tests.fakes.fake_messages_api import FakeMessagesAPI
from tests.fakes.scripted_reasoner import GARBAGE, ScriptedReasoner
from tests.support.ltaa_support import run

CRANE, LIFTER, HAULER, ARM = 0, 1, 2, 3
ROBOTS = (
    Robot("crane", {"heavy": 0.9, "careful": 0.2}, label="Crane", zone="north"),
    Robot("lifter", {"heavy": 0.8, "careful": 0.4}, label="Lifter", zone="north"),
    # The best heavy lifter, but 30 minutes away in the south.
    Robot("hauler", {"heavy": 0.95, "careful": 0.1}, label="Hauler", zone="south"),
    Robot("arm", {"heavy": 0.3, "careful": 0.95}, label="Arm", zone="south"),
)
TASKS = (
    # Due at 40: a team with the hauler (arriving at 30) would end at 60.
    Task(
        "beam", "Lift beam", ("heavy",), duration=30, zone="north", deadline=40, team={"heavy": 2}
    ),
    Task("sweep", "Sweep", ("careful",), duration=10, zone="south"),
    Task(
        "panel",
        "Fix panel",
        ("heavy", "careful"),
        duration=20,
        zone="south",
        team={"heavy": 1, "careful": 1},
        # Start to start: 10 minutes after the beam starts; finish to finish: not before it ends.
        after=(Link("beam", "SS", 10), Link("beam", "FF", 0)),
    ),
    Task("carry", "Carry", ("heavy",), duration=15, zone="north", after=("beam",)),
)
INSTANCE = Instance(TASKS, ROBOTS, travel={"north": {"south": 30}})
PROBLEM = Problem.build(INSTANCE, Mode.SUCCESS_FOCUSED)


def first_team_context(problem: Problem = PROBLEM) -> DecisionContext:
    """The first decision (the beam, due at 40), as the graph's nodes build it."""
    progress = TimedProgress(problem)
    t = progress.current()
    loads = [0] * problem.instance.n_robots
    later = progress.later(t)
    view = task_view(problem, t, loads, None, decided=progress.decided, later=later)
    state = {"task_index": t, "loads": loads, "view": view, "attempt": 1}
    return decision_context(
        problem,
        state,
        timing=progress.options(t),
        allocated=progress.decided,
        team_time=functools.partial(progress.team_option, t),
        later=later,
    )


def test_a_team_starts_when_its_last_member_arrives_and_holds_every_lane() -> None:
    progress = TimedProgress(PROBLEM)
    assert progress.current() == 0
    far = progress.team_option(0, (CRANE, HAULER))
    assert (far.start, far.end, far.robot) == (30, 60, HAULER) and not far.allowed
    assert "deadline" in far.why_not
    near = progress.team_option(0, (CRANE, LIFTER))
    assert (near.start, near.end) == (0, 30) and near.allowed
    progress.place(0, CRANE, (CRANE, LIFTER))
    # Both members' lanes are taken until 30: the panel needs one of them, who must then
    # travel south (30 min), and the FF link keeps it from ending before the beam.
    assert progress.team_option(2, (LIFTER, ARM)).start == 60
    assert progress.team_option(2, (HAULER, ARM)).start == 10  # SS +10 from the beam's start


def test_the_prompt_gives_each_robots_time_and_the_teams_start_and_end() -> None:
    ctx = first_team_context()
    assert ctx.team is not None and ctx.team.best == (CRANE, LIFTER)
    text = user_prompt(ctx)
    assert (
        "- Hauler [hauler]: load 0 (dev -1.5), NOT allowed; free 0, travel 30, 30-60 (misses"
        in text
    )
    assert "- best: heavy: Crane, Lifter (S 85.0%, loads 0), in time 0-30, slack 10" in text
    assert "missing the deadline or a shift: not allowed" in text


def test_a_team_that_misses_the_deadline_is_hard_invalid() -> None:
    ctx = first_team_context()
    good = compose_answer(ctx)
    assert validate_text(good, ctx).accepted
    late = good.replace("Lifter", "Hauler")
    verdict = validate_text(late, ctx)
    assert not verdict.accepted and verdict.quality == 0.0
    assert verdict.hard_invalid is not None and "deadline" in verdict.hard_invalid


def test_a_member_whose_shift_ends_first_rules_the_team_out() -> None:
    robots = (
        ROBOTS[0],
        Robot("lifter", {"heavy": 0.8, "careful": 0.4}, zone="north", available=(0, 20)),
        *ROBOTS[2:],
    )
    problem = Problem.build(Instance(TASKS, robots, travel=INSTANCE.travel), Mode.SUCCESS_FOCUSED)
    option = TimedProgress(problem).team_option(0, (CRANE, LIFTER))
    assert not option.allowed and "lifter's shift" in option.why_not


def _teams(decisions: list[DecisionRecord]) -> list[tuple[object, ...]]:
    return [(d.task_index, d.team, d.start, d.end) for d in decisions]


def test_the_graph_decides_every_task_in_time_and_its_schedule_is_feasible() -> None:
    solution = get_solver("ltaa").solve(PROBLEM)
    details = solution.details
    assert details["schedule_violations"] == [], details["schedule_violations"]
    schedule = details["schedule"]
    assert check_schedule(PROBLEM, schedule) == []
    slots = {s.task: s for s in schedule.slots}
    assert slots[0].team == (CRANE, LIFTER) and (slots[0].start, slots[0].end) == (0, 30)
    panel = slots[2]
    assert panel.start >= slots[0].start + 10 and panel.end >= slots[0].end  # SS and FF
    assert set(solution.teams) == {0, 2}
    for d in details["decisions"]:
        assert d["fallback"] is False


def test_the_fallback_takes_the_best_success_team_in_time() -> None:
    rec, _ = run(PROBLEM, ScriptedReasoner(then=GARBAGE), max_retries=1)
    decisions = {d.task_index: d for d in rec.decisions()}
    beam = decisions[0]
    assert beam.fallback and [m["robot"] for m in beam.team or []] == ["crane", "lifter"]
    assert (beam.start, beam.end) == (0, 30)
    assert "free in time" in beam.reasoning


def test_baseline_team_is_decided_in_precedence_order_with_a_feasible_schedule() -> None:
    problem = Problem.build(timed_scenario("baseline_team").instance, Mode.BALANCED)
    rec, _ = run(problem, RulesReasoner())
    decisions = rec.decisions()
    assert len(decisions) == problem.instance.n_tasks
    teams = [d for d in decisions if d.team]
    assert len(teams) == 7 and all(d.start is not None for d in teams)
    first_tries = [a.user_prompt for a in rec.attempts() if a.attempt == 1]
    assert max(len(p) for p in first_tries) < TARGET_USER_PROMPT_CHARS
    solution = get_solver("ltaa").solve(problem)
    assert solution.details["schedule_violations"] == []
    tm = problem.instance.timing
    order = {d.task_index: d.seq or 0 for d in decisions}  # its place in the decision order
    for t in range(tm.n_tasks):
        assert all(order[p] < order[t] for p in tm.predecessors[t])


def test_both_sdk_fakes_answer_timed_team_decisions_as_the_rules_reasoner_does() -> None:
    rules, _ = run(PROBLEM, RulesReasoner())
    with FakeMessagesAPI() as api:
        anthropic = AnthropicReasoner(
            api_key="test-key", base_url=api.base_url, timeout=5.0, transport_retries=1
        )
        by_messages, _ = run(PROBLEM, anthropic)
    with FakeChatCompletionsAPI() as api:
        openai = OpenAIReasoner(base_url=api.base_url, model="qwen-test", timeout=5.0)
        by_chat, _ = run(PROBLEM, openai)
    for rec in (by_messages, by_chat):
        assert all(not d.fallback for d in rec.decisions())
        assert _teams(rec.decisions()) == _teams(rules.decisions())


def test_guidance_in_time_follows_the_exact_team_schedule_and_stores_its_teams() -> None:
    """docs/schedules.md#guidance-in-time on team tasks: the plan is the multi-skill model's,
    solved on the deterministic budget; it keeps each team task's members (stored with the
    plan, read back the same), and the guided graph follows them to the plan's makespan."""
    plan = plan_guidance(PROBLEM)
    assert plan.budget["deterministic_budget"] and plan.budget["workers"] == 1
    assert set(plan.teams) == {0, 2} and plan.teams[0] == (CRANE, LIFTER)
    assert GuidancePlan.from_json(plan.as_json()) == plan
    solution = get_solver("ltaa").solve(PROBLEM, options={"guidance": "optimizer"})
    assert solution.details["schedule_violations"] == []
    assert solution.teams == dict(plan.teams)
    assert solution.details["schedule"].makespan == plan.budget["makespan"]


def _random_timed_team_instance(rng: random.Random) -> Instance:
    zones = ["a", "b", "c"]
    robots = tuple(
        Robot(
            f"r{i}",
            {f: round(rng.uniform(0.2, 0.95), 2) for f in ("heavy", "careful")},
            zone=rng.choice(zones),
        )
        for i in range(rng.randint(3, 5))
    )
    tasks: list[Task] = []
    for k in range(rng.randint(5, 9)):
        earlier = [t.id for t in tasks]
        after: tuple[str | Link, ...] = ()
        if earlier and rng.random() < 0.6:
            pred = rng.choice(earlier)
            after = (Link(pred, rng.choice(["FS", "SS", "FF"]), rng.choice([0, 5, -5])),)
        team = rng.choice([None, {"heavy": 2}, {"heavy": 1, "careful": 1}])
        features = tuple(team) if team else (rng.choice(["heavy", "careful"]),)
        duration = rng.randint(5, 30)
        tasks.append(
            Task(
                f"t{k}",
                f"T{k}",
                features,
                duration=duration,
                zone=rng.choice(zones),
                after=after,
                team=team,
            )
        )
    travel = {"a": {"b": 4, "c": 9}, "b": {"c": 6}}
    return Instance(tuple(tasks), robots, travel=travel)


@pytest.mark.parametrize("seed", range(6))
def test_random_timed_team_instances_get_feasible_schedules_with_valid_teams(seed: int) -> None:
    """No deadlines or shifts here, so nothing excuses a broken rule: precedence and typed
    links, one place at a time with travel, every team's units covered by distinct robots."""
    instance = _random_timed_team_instance(random.Random(seed))
    problem = Problem.build(instance, Mode.BALANCED)
    solution = get_solver("ltaa").solve(problem, seed=seed)
    schedule = solution.details["schedule"]
    assert check_schedule(problem, schedule) == [], seed
    for t, task in enumerate(instance.tasks):
        if task.team:
            members = solution.teams[t]
            assert len(set(members)) == len(members) == sum(task.team.values())
            assert schedule.slots[t].team == members
