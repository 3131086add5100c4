"""Large-neighbourhood search (LNS) for the large-instance path.

Past `EXACT_LIMIT` no CP-SAT model of the whole plan finds anything in a minute (measured
at 1,000 x 20, `large.py`), but the exact model of a few dozen tasks around a schedule
solves in well under a second. So, from the best schedule so far, repeatedly: choose a
neighbourhood (the tasks running around a task of the critical path, around a random
time, or on the robot that ends last and a few others in a window), re-solve it with
CP-SAT (`lns_model.Neighbourhood`: the rest keeps its robots and orders, its times
float), re-time the answer at earliest times, and keep it if it passes `check_schedule`
and is better: a shorter makespan, or the same makespan with a smaller sum of ends (where
the speeds decide the robots, first the robots' ends from the latest down, then their
work and travel: `_better`; a strict order, so it cannot cycle). Under
`success_then_makespan` the free tasks keep their ES share exactly and may only use
ES-optimal pairs (`success_pairs`), so ES stays at its proven optimum. The neighbourhood
grows when CP-SAT solves it to optimality and shrinks when it does not within its slice
of time. Every CP-SAT run stops at the call's
time limit; nothing it finds is called optimal.
"""

from __future__ import annotations

import random
import time
from collections.abc import Sequence
from dataclasses import dataclass

from ortools.sat.python import cp_model

from app.domain.errors import DomainError
from app.domain.links import ancestors_through
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.list_schedule import sequence_schedule
from app.domain.scheduling.schedule import EPS, Schedule, StepKind
from app.domain.time_model import TimeModel
from app.solvers.cpsat.common import model_cost, speeds_decide
from app.solvers.cpsat.lns_model import Neighbourhood
from app.solvers.cpsat.outcome import Setup

SLICE = 0.5  # deterministic units of CP-SAT per neighbourhood (~1.5 s of CPU here)
# Measured at 1,000 x 20: 40 tasks across all robots (times after the window floating)
# took 1-2 s to solve, 40 tasks on 3-5 robots (the rest fixed) 0.03-0.1 s. Each kind of
# neighbourhood keeps its own size, grown while CP-SAT solves it fast and to optimality,
# shrunk when it does not.
START_SIZE = {"window": 30, "robots": 40, "speed": 40, "zone": 40}
MIN_SIZE, MAX_SIZE = 6, 250
FAST, SLOW = 0.3, 0.8  # deterministic units
GROW, SHRINK = 1.2, 0.8
# How often each kind is drawn; `speed` and `zone` only where the speeds decide the
# robots and travel matters (`common.speeds_decide`; docs/schedules.md#anytime).
SHARES = {"robots": 0.5, "window": 0.5}
SHARES_UNRELATED = {"robots": 0.3, "window": 0.3, "speed": 0.2, "zone": 0.2}
QUICK_PARTNERS = 3  # the robots quickest at the chosen task, besides its own


@dataclass
class LnsReport:
    neighbourhoods: int = 0
    improved: int = 0
    rejected: int = 0  # answers that failed check_schedule (kept out, counted to see)
    wall_s: float = 0.0
    start_makespan: float = 0.0
    end_makespan: float = 0.0

    def stage(self) -> dict[str, object]:
        return {
            "stage": "lns",
            "status": "FEASIBLE",
            "wall_s": round(self.wall_s, 3),
            "neighbourhoods": self.neighbourhoods,
            "improved": self.improved,
            "rejected": self.rejected,
            "objective": self.end_makespan,
            "start_objective": self.start_makespan,
        }


def improve(
    setup: Setup,
    candidates: Sequence[Sequence[int]],
    start: Schedule | None = None,
    seconds: float | None = None,
    slice_units: float = SLICE,
    loaded_first: bool = False,
    effort_first: bool = False,
    tail_minutes: float | None = None,
    compact: bool = False,
) -> LnsReport | None:
    """Run LNS from `start` (default: the best schedule so far) for `seconds` of budget
    (default: all that is left); None if there is nothing to start from or no time.

    Deterministic: the neighbourhoods, their sizes and CP-SAT's seeds follow from the seed
    and the answers alone, and a neighbourhood runs only when its whole slice (and its
    modelled build cost) fits in the budget, so a larger budget runs the same
    neighbourhoods first and then more (docs/schedules.md#anytime). `loaded_first` (the
    large path): the robots neighbourhood starts from the most loaded robots on the
    critical path and lets the tasks after it float in time, as the window does.
    `effort_first` (where the speeds decide the robots): of two plans of the same makespan
    the one whose robots end earlier, from the latest down, is better, then the one whose
    robots work and travel less, before the sum of ends (`_better`; measured in
    docs/schedules.md#anytime). `tail_minutes`: of the tasks after a neighbourhood, only
    those starting within that many minutes of its end float; `compact`: the smaller
    model of the same neighbourhood (`Neighbourhood`)."""
    search, feasible = setup.search, setup.feasible
    current = start or feasible.best()
    limit = search.remaining() if seconds is None else min(search.remaining(), seconds)
    stop_at = search.spent + limit
    if current is None or limit < slice_units:
        return None
    problem = setup.problem
    began = time.perf_counter()
    rng = random.Random(search.seed)
    ancestors = _ancestor_masks(setup)
    movable = [
        t
        for t in range(problem.instance.n_tasks)
        if t not in problem.pinned and len(candidates[t]) >= 1
    ]
    report = LnsReport(start_makespan=current.makespan, end_makespan=current.makespan)
    size = {kind: float(n) for kind, n in START_SIZE.items()}
    shares = SHARES_UNRELATED if speeds_decide(setup.problem, setup.weights, candidates) else SHARES
    build = 0.0  # the last neighbourhood's modelled build cost: the next one's estimate
    while (
        movable and search.spent + build + slice_units <= stop_at + 1e-9 and search.remaining() > 0
    ):
        search.need(search.spent + build + slice_units)
        kind = _draw(rng, shares)
        how = (int(size[kind]), kind)
        if kind in ("speed", "zone"):
            free, robots = _choose_by_site(rng, setup, current, movable, how, candidates)
        else:
            free, robots = _choose(rng, current, movable, how, candidates, loaded_first)
        allowed = candidates
        if robots is not None:  # an exchange among these robots only
            allowed = [[r for r in c if r in robots] for c in candidates]
        # On the large path the robots' tails float too: a task swapped onto a robot at the
        # cap's load moves its successors instead of meeting them frozen in time.
        floating = kind == "window" or loaded_first
        hood = Neighbourhood(
            setup, current, free, allowed, ancestors, floating, tail_minutes, robots, compact
        )
        build = model_cost(hood.model)
        search.charge(build)
        status, solver = _solve(hood.model, setup, rng, slice_units)
        report.neighbourhoods += 1
        used = solver.deterministic_time
        if status == "OPTIMAL" and used < FAST * slice_units / SLICE:
            size[kind] = min(MAX_SIZE, size[kind] * GROW)
        elif status != "OPTIMAL" or used > SLOW * slice_units / SLICE:
            size[kind] = max(MIN_SIZE, size[kind] * SHRINK)
        if status not in ("OPTIMAL", "FEASIBLE"):
            continue
        schedule = _retimed(setup, *hood.read(solver))
        if schedule is None:
            report.rejected += 1
            continue
        if _better(schedule, current, effort_first):
            feasible.offer(schedule)
            current = schedule
            report.improved += 1
            search.mark(current.makespan)
    report.wall_s = time.perf_counter() - began
    report.end_makespan = current.makespan
    search.stages.append(report.stage())
    return report


def _choose(
    rng: random.Random,
    current: Schedule,
    movable: list[int],
    how: tuple[int, str],
    candidates: Sequence[Sequence[int]],
    loaded_first: bool = False,
) -> tuple[list[int], set[int] | None]:
    """`size` movable tasks close in time to a centre: a task on the critical path, a random
    minute, or (robots) the tasks of a robot that ends last (with `loaded_first`: of one of
    the three most loaded robots on the critical path) and of two to four others."""
    size, kind = how
    slots = current.slots
    pool, chosen = movable, None
    if kind == "window" and rng.random() < 0.6:
        critical = [
            s.task for s in current.critical_path if s.kind is StepKind.TASK and s.task is not None
        ]
        centre = slots[rng.choice(critical)].start if critical else rng.uniform(0, current.makespan)
    elif kind == "window":
        centre = rng.uniform(0, current.makespan)
    else:
        # Where the makespan is: one of the three robots that end last, its tasks around a
        # random one of them, with two to four robots that could take some of those tasks
        # (the earliest to finish first: they have room), all in the same time window.
        ends = _last_ends(current)
        late = (_loaded(current) if loaded_first else []) or sorted(ends, key=lambda r: -ends[r])[
            :3
        ]
        last = rng.choice(late)
        mine = [t for t in movable if slots[t].robot == last]
        centre = slots[rng.choice(mine)].start if mine else rng.uniform(0, current.makespan)
        near = sorted(mine, key=lambda t: abs(slots[t].start - centre))[: max(1, size // 4)]
        partners = sorted({r for t in near for r in candidates[t]} - {last}, key=lambda r: ends[r])
        if not partners:
            partners = sorted(set(ends) - {last}, key=lambda r: ends[r])
        chosen = {last, *rng.sample(partners[:6], min(len(partners[:6]), rng.randint(2, 4)))}
        pool = [t for t in movable if slots[t].robot in chosen]
    return sorted(pool, key=lambda t: (abs(slots[t].start - centre), t))[:size], chosen


def _draw(rng: random.Random, shares: dict[str, float]) -> str:
    """A kind of neighbourhood, by one draw over `shares` in its order."""
    x = rng.random()
    for kind, share in shares.items():
        x -= share
        if x < 0:
            return kind
    return kind


def _choose_by_site(
    rng: random.Random,
    setup: Setup,
    current: Schedule,
    movable: list[int],
    how: tuple[int, str],
    candidates: Sequence[Sequence[int]],
) -> tuple[list[int], set[int] | None]:
    """Around a task of a loaded robot on the critical path, among a few robots only:
    `speed`, the robots quickest at the task that is slowest there for its robot (the
    earliest finish hands work to whoever is free, and a minute of slow work is a minute
    of makespan on a loaded robot); `zone`, the robots with work in the zone of a task
    there (the neighbourhood may then give one robot a run of tasks in that zone instead of
    each crossing the site). The tasks of those robots closest in time are freed."""
    size, kind = how
    tm, slots = setup.problem.instance.timing, current.slots
    loaded = _loaded(current)
    late = loaded or sorted({s.robot for s in slots})
    robot = rng.choice(late)
    mine = [t for t in movable if slots[t].robot == robot]
    if not mine:
        return _choose(rng, current, movable, (size, "window"), candidates)
    if kind == "speed":
        pivot = slots[rng.choice(mine)].start
        near = sorted(mine, key=lambda t: (abs(slots[t].start - pivot), t))[: max(4, size // 4)]
        centre = max(near, key=lambda t: (_excess(tm, t, robot, candidates[t]), -t))
        quick = sorted(
            (r for r in candidates[centre] if r != robot),
            key=lambda r: (tm.duration(centre, r), r),
        )
        chosen = {robot, *quick[:QUICK_PARTNERS]}
    else:
        centre = rng.choice(mine)
        zone = tm.task_zone[centre]
        at = slots[centre].start
        others = sorted(
            {
                slots[t].robot
                for t in movable
                if tm.task_zone[t] == zone and slots[t].robot != robot and robot in candidates[t]
            },
            key=lambda r: (
                min(abs(slots[t].start - at) for t in movable if slots[t].robot == r),
                r,
            ),
        )
        chosen = {robot, *others[: rng.randint(2, 3)]}
    pool = [t for t in movable if slots[t].robot in chosen]
    at = slots[centre].start
    return sorted(pool, key=lambda t: (abs(slots[t].start - at), t))[:size], chosen


def _excess(tm: TimeModel, t: int, robot: int, robots: Sequence[int]) -> float:
    """Minutes robot `robot` takes at task t beyond the quickest robot allowed."""
    return tm.duration(t, robot) - min(tm.duration(t, r) for r in robots)


def _loaded(current: Schedule) -> list[int]:
    """The three robots on the critical path with the most work and travel: where the
    makespan is made (the robot that ends last often only does a chain's last task)."""
    work = current.robot_time
    on_path = {s.robot for s in current.critical_path if s.kind is StepKind.TASK}
    return sorted(
        (r for r in on_path if r is not None), key=lambda r: (-work[r].busy - work[r].travel, r)
    )[:3]


def _solve(
    model: cp_model.CpModel, setup: Setup, rng: random.Random, units: float
) -> tuple[str, cp_model.CpSolver]:
    search = setup.search
    solver = search.solver(units)
    solver.parameters.random_seed = rng.randrange(1 << 30)
    # A small model: probing and repeated presolve cost more than they save here.
    solver.parameters.cp_model_probing_level = 0
    solver.parameters.max_presolve_iterations = 1
    status = solver.status_name(solver.solve(model))
    search.book(solver)
    return status, solver


def _retimed(setup: Setup, robots: list[int], starts: list[float]) -> Schedule | None:
    """The answer's per-robot orders at their earliest times, if that passes the check and
    the objective's ES condition."""
    problem = setup.problem
    sequences: list[list[int]] = [[] for _ in range(problem.instance.n_robots)]
    for t in sorted(range(len(robots)), key=lambda k: (starts[k], k)):
        sequences[robots[t]].append(t)
    try:
        schedule = sequence_schedule(problem, sequences)
    except (ValueError, DomainError):
        return None
    if check_schedule(problem, schedule):
        return None
    if not setup.feasible.condition(setup.weights.of(schedule.assignment)):
        return None
    return schedule


def _better(new: Schedule, old: Schedule, effort_first: bool = False) -> bool:
    """A strict order: the makespan, then (with `effort_first`) the robots' last ends
    from the latest down (leximax) and the robots' work and travel together, then the sum
    of ends."""
    if new.makespan < old.makespan - EPS:
        return True
    if new.makespan > old.makespan + EPS:
        return False
    if effort_first:
        # Where most robots end within minutes of the makespan, no neighbourhood of a few
        # robots shortens it at once; one that ends one of them earlier is a step there.
        for ours, theirs in zip(_robot_ends(new), _robot_ends(old), strict=True):
            if abs(ours - theirs) > EPS:
                return ours < theirs
        ours, theirs = _effort(new), _effort(old)
        if abs(ours - theirs) > EPS:
            return ours < theirs
    return _sum_ends(new) < _sum_ends(old) - EPS


def _last_ends(schedule: Schedule) -> dict[int, float]:
    """Each robot with work: the end of its last task."""
    ends: dict[int, float] = {}
    for s in schedule.slots:
        for r in s.members:
            ends[r] = max(ends.get(r, 0.0), s.end)
    return ends


def _robot_ends(schedule: Schedule) -> list[float]:
    """Each robot's last end (0 for a robot without work), the latest first."""
    ends = _last_ends(schedule)
    return sorted((ends.get(r, 0.0) for r in range(len(schedule.robot_time))), reverse=True)


def _effort(schedule: Schedule) -> float:
    """Minutes the robots work and travel: what a plan of the same makespan spends."""
    return sum(line.busy + line.travel for line in schedule.robot_time)


def _sum_ends(schedule: Schedule) -> float:
    return sum(s.end for s in schedule.slots)


def _ancestor_masks(setup: Setup) -> list[int]:
    """Per task, a bitmask of the tasks that must end before it starts (none through a
    task with a pinned start: a fact waits for nothing)."""
    problem = setup.problem
    tm = problem.instance.timing
    masks = [0] * tm.n_tasks
    for t in tm.order:
        if t in problem.pinned_starts:
            continue
        for arc in tm.links[t]:
            masks[t] |= ancestors_through(arc, masks[arc.pred])
    return masks
