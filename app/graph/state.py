"""Graph state (O(robots), checkpointed at every super-step) and the run-scoped context.

SqliteSaver rewrites the whole state at every step, so nothing here may grow with the run:
prompts, replies, attempts and decisions go through the Recorder. The only text is the
`decision` scratch, which lives from finalize to store_and_route and is then cleared.
Every channel adds a version string to each checkpoint and a row per write, so values
derived together share one channel (`view`).
"""

from __future__ import annotations

import bisect
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypedDict

from langgraph.runtime import Runtime

from app.domain.decision import GuidedChoice
from app.domain.metrics import balance_score, severity
from app.domain.modes import strategic_weights
from app.domain.phases import balance_urgency, detect_phase
from app.domain.problem import Problem
from app.graph.recorder import Recorder
from app.graph.review import ReviewGate
from app.graph.timing import TimedCursor, first_task
from app.graph.validation import DEFAULT_QUALITY_THRESHOLD
from app.graph.verdicts import VerdictCache
from app.reasoners.base import Reasoner
from app.reasoners.structured import ReplyFormat

DEFAULT_MAX_RETRIES = 3


# Optimizer guidance: (task index, loads before) -> the robot to prefer (optionally with
# what each alternative would cost), or None.
Guidance = Callable[[int, Sequence[int]], int | GuidedChoice | None]
# Regret: (task index, loads before, members) -> expected success the decision gave away;
# members is (robot,) for a single-robot task, the team in unit order for a team task.
Regret = Callable[[int, Sequence[int], tuple[int, ...]], float]


class TaskView(TypedDict):
    """What detect_phase derives for the current task (one channel: fewer checkpoint rows)."""

    phase: str
    progress: float
    balance: float  # balance score of the state's loads
    severity: str
    weights: list[float]  # strategic success, balance weights for this phase
    feasible: list[int]  # robots whose choice keeps the cap satisfiable
    guided_robot: int | None
    guided_costs: list[float | None] | None  # success points each robot would give away
    guided_team: list[int] | None  # a team task's optimal team (docs/allocation.md#teams)


class LTAAState(TypedDict, total=False):
    task_index: int  # the task being decided; == n_tasks when the run is done
    done: bool  # set by store_and_route after the last task (the end router reads only this)
    loads: list[int]  # per robot, before the current decision until update_workload
    view: TaskView
    attempt: int  # 1-based attempt of the current task; 0 between tasks
    tier: int  # retry tier of the current attempt
    accepted: bool
    fallback: bool
    robot: int | None  # the robot chosen for the current task (accepted or fallback)
    decision: dict[str, Any] | None  # finalize -> store_and_route scratch, then cleared
    # docs/reasoners.md#bounded-cost: decided tasks in a row that fell back (held once the
    # model is given up: app.reasoners.give_up).
    failing: int


@dataclass(frozen=True)
class ModelUse:
    """How a run asks its model, and when it stops asking; stored with the run."""

    # docs/reasoners.md#structured-replies: how the prompts ask for the answer, and whether the
    # reasoner is handed the decision's JSON Schema (markdown: the paper's sections).
    reply_format: ReplyFormat = ReplyFormat.MARKDOWN
    # docs/reasoners.md#bounded-cost: after this many tasks in a row ended in the fallback the
    # model is asked no more (0: never; the reasoners that call no model never give up).
    give_up_after: int = 0


@dataclass
class GraphContext:
    """Run-scoped inputs passed as LangGraph runtime context (never checkpointed)."""

    problem: Problem
    reasoner: Reasoner
    recorder: Recorder
    quality_threshold: float = DEFAULT_QUALITY_THRESHOLD
    max_retries: int = DEFAULT_MAX_RETRIES
    guidance: Guidance | None = None
    regret: Regret | None = None
    # The run's review policy (docs/reviews.md#which-decisions-wait-for-review), or a replay's
    # recorded resolutions; None: no review.
    review: ReviewGate | None = None
    verdicts: VerdictCache = field(default_factory=VerdictCache)
    # docs/estimates.md#using-the-estimates: robot -> feature -> (basis, reports) of rates learned
    # from the site (the prompt says so); empty: every rate is the configured one.
    rate_notes: Mapping[str, Mapping[str, tuple[str, int]]] = field(default_factory=dict)
    # docs/schedules.md#the-order-of-decisions: on a timed instance, the robots' timelines and the
    # decision order.
    timed: TimedCursor = field(default_factory=TimedCursor)
    model_use: ModelUse = field(default_factory=lambda: ModelUse())

    @property
    def max_attempts(self) -> int:
        return 1 + self.max_retries


def initial_state(problem: Problem) -> dict[str, Any]:
    """The state before the first free task: with pins (a revision, or /allocate `pinned`)
    the graph decides only the unpinned tasks, starting from the loads the pins make."""
    loads = list(problem.initial_loads)
    first = first_task(problem) if problem.instance.timed else next_task(problem, -1)
    return {
        "task_index": first,
        "done": first >= problem.instance.n_tasks,
        "loads": loads,
        "view": task_view(problem, min(first, problem.instance.n_tasks - 1), loads, None),
        "attempt": 0,
        "tier": 0,
        "accepted": False,
        "fallback": False,
        "robot": None,
        "decision": None,
        "failing": 0,
    }


def task_view(
    problem: Problem,
    task_index: int,
    loads: Sequence[int],
    guided_robot: int | None,
    guided_costs: Sequence[float | None] | None = None,
    decided: int | None = None,
    guided_team: Sequence[int] | None = None,
    later: Sequence[int] | None = None,
) -> TaskView:
    """`decided`: the graph's decisions so far, when it does not decide in queue order (a
    timed instance); else they are the free tasks before `task_index`. `later`: the free
    tasks still to decide after this one, on a timed instance with teams (whose completion
    check then looks at them rather than at the tasks after it in the queue)."""
    n = problem.instance.n_tasks
    # docs/living-plans.md#balance-and-phases: p = (pins + tasks decided so far) / tasks; with no
    # pins, task_index / n.
    if decided is None:
        allocated = problem.allocated_before(task_index)
        remaining = problem.remaining_after(task_index)
    else:
        allocated = len(problem.pinned) + decided
        remaining = len(problem.free_tasks) - decided - 1
    phase = detect_phase(allocated, n)
    weights = strategic_weights(problem.mode, phase)
    return {
        "phase": phase.value,
        "progress": balance_urgency(allocated, n),
        "balance": balance_of(problem, loads),
        "severity": severity_of(problem, loads),
        "weights": [weights.success, weights.balance],
        # Eligible robots only (docs/allocation.md#teams); in queue order, only those after
        # whose choice every later task keeps an eligible robot within the cap.
        "feasible": problem.feasible_robots(
            task_index, loads, remaining, in_order=decided is None if later is None else later
        ),
        "guided_robot": guided_robot,
        "guided_costs": list(guided_costs) if guided_costs is not None else None,
        "guided_team": list(guided_team) if guided_team is not None else None,
    }


def next_task(problem: Problem, after: int) -> int:
    """The next task the graph decides after queue position `after` (n_tasks: none left)."""
    free = problem.free_tasks
    i = bisect.bisect_right(free, after)  # no slice: a copy of the rest of the queue per task
    return free[i] if i < len(free) else problem.instance.n_tasks


def balance_of(problem: Problem, loads: Sequence[int]) -> float:
    """Balance score over the robots in the balance (unavailable ones stand outside it)."""
    return balance_score(problem.cap.balanced(loads), problem.target)


def severity_of(problem: Problem, loads: Sequence[int]) -> str:
    return severity(problem.cap.balanced(loads), problem.target).value


class Node(Protocol):
    """A graph node. A protocol, not a Callable alias: LangGraph passes `runtime` by keyword,
    and its add_node overloads accept only callables whose second parameter is so named."""

    def __call__(self, state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]: ...
