"""A plan in time (docs/schedules.md#a-schedule-and-its-check): when each task runs, on which robot,
where.

`build_schedule` is the one constructor: a robot and a start per task are the decision;
everything else (ends, zones, travel before each task, the makespan, per-robot
busy/idle/travel minutes and the critical path) is derived from the instance, so two
solvers that make the same decision report the same schedule.

Per robot, `idle` counts the minutes of its shift up to the makespan that it spends
neither working nor travelling (a robot whose shift starts after the makespan has none).
The critical path is the chain of tasks, travels and waits, from minute 0 to the
makespan, that fixes the makespan: walking back from the task that ends last, each task
started when its predecessor ended (precedence), when its robot had finished its previous
task and travelled (robot), or when a release, a shift start, `not_before` or a pinned
start allowed it (a wait).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from enum import StrEnum
from typing import TYPE_CHECKING, Any

from app.domain.links import allowed_start

if TYPE_CHECKING:
    from app.domain.problem import Problem
    from app.domain.time_model import TimeModel

EPS = 1e-6  # minutes: equal within this, as solver times come back as scaled integers


@dataclass(frozen=True)
class Slot:
    task: int
    robot: int  # a team task's: the member covering its first unit
    start: float
    end: float
    zone: str | None
    travel: float  # minutes the robot moved just before this task
    # A team task (docs/allocation.md#teams): the robot covering each unit, in unit order,
    # and the minutes each of them moved just before it; () for a single-robot task.
    team: tuple[int, ...] = ()
    team_travel: tuple[float, ...] = ()

    @property
    def members(self) -> tuple[int, ...]:
        """Every robot busy with the task over [start, end]."""
        return self.team or (self.robot,)

    def travel_of(self, robot: int) -> float:
        """Minutes `robot` (a member) moved just before this task."""
        if not self.team:
            return self.travel
        return self.team_travel[self.team.index(robot)]


@dataclass(frozen=True)
class RobotTime:
    busy: float
    idle: float
    travel: float


class StepKind(StrEnum):
    TASK = "task"
    TRAVEL = "travel"
    WAIT = "wait"


@dataclass(frozen=True)
class Step:
    kind: StepKind
    start: float
    end: float
    task: int | None  # the task worked, travelled to or waited for
    robot: int | None
    cause: str  # why the next step could not start earlier


@dataclass(frozen=True)
class Schedule:
    slots: tuple[Slot, ...]  # one per task, in queue order
    makespan: float
    robot_time: tuple[RobotTime, ...]
    critical_path: tuple[Step, ...]
    start: datetime | None  # wall-clock time of minute 0

    @property
    def assignment(self) -> list[int]:
        return [s.robot for s in self.slots]

    @property
    def teams(self) -> dict[int, tuple[int, ...]]:
        """Task -> the robot covering each unit, for the team tasks."""
        return {s.task: s.team for s in self.slots if s.team}

    def sequences(self, n_robots: int) -> list[list[int]]:
        """Per robot, its tasks in time order (a team task in every member's)."""
        out: list[list[int]] = [[] for _ in range(n_robots)]
        for slot in sorted(self.slots, key=lambda s: (s.start, s.end, s.task)):
            for r in slot.members:
                out[r].append(slot.task)
        return out

    def wall_clock(self, minute: float) -> str | None:
        """RFC 3339 time of a minute of the plan, in `start`'s offset; None without start."""
        if self.start is None:
            return None
        try:
            return (self.start + timedelta(minutes=minute)).isoformat()
        except OverflowError:  # past the year 9999: no wall-clock time to give
            return None

    def to_dict(self, problem: Problem) -> dict[str, Any]:
        """Plain JSON: task ids and robot names instead of indexes."""
        tasks, robots = problem.instance.tasks, problem.instance.robots

        def name(r: int | None) -> str | None:
            return None if r is None else robots[r].name

        return {
            "start": None if self.start is None else self.start.isoformat(),
            "makespan": self.makespan,
            "tasks": [
                {
                    "task_id": tasks[s.task].id,
                    "robot": robots[s.robot].name,
                    "start": s.start,
                    "end": s.end,
                    "start_at": self.wall_clock(s.start),
                    "end_at": self.wall_clock(s.end),
                    "zone": s.zone,
                    "travel": s.travel,
                }
                | _team_dict(problem, s)
                for s in self.slots
            ],
            "robots": {
                robots[r].name: {"busy": t.busy, "idle": t.idle, "travel": t.travel}
                for r, t in enumerate(self.robot_time)
            },
            "critical_path": [
                {
                    "kind": step.kind.value,
                    "task_id": None if step.task is None else tasks[step.task].id,
                    "robot": name(step.robot),
                    "start": step.start,
                    "end": step.end,
                    "cause": step.cause,
                }
                for step in self.critical_path
            ],
        }


def _team_dict(problem: Problem, slot: Slot) -> dict[str, Any]:
    """A team task's members as JSON: one entry per unit (robot, feature, its travel)."""
    if not slot.team:
        return {}
    robots, units = problem.instance.robots, problem.instance.units[slot.task]
    return {
        "team": [
            {"robot": robots[r].name, "feature": f, "travel": m}
            for r, f, m in zip(slot.team, units, slot.team_travel, strict=True)
        ]
    }


# Per task, per member: (member, the member's previous task or None, its travel before).
Previous = tuple[tuple[int, int | None, float], ...]


def build_schedule(
    problem: Problem,
    robots: Sequence[int],
    starts: Sequence[float],
    ends: Sequence[float] | None = None,
    teams: Mapping[int, tuple[int, ...]] | None = None,
) -> Schedule:
    """The schedule of one robot and one start per task (queue order). Ends default to
    start + the robot's duration; pass them for a plan made elsewhere (e.g. a reply).
    `teams` gives a team task's robot per unit (docs/allocation.md#teams): every member
    works over the same [start, end] and travels to the task's zone on its own way."""
    tm = problem.instance.timing
    n = tm.n_tasks
    teams = teams or {}
    if len(robots) != n or len(starts) != n:
        raise ValueError(f"a schedule needs one robot and one start for each of the {n} tasks")
    if ends is None:
        ends = [starts[t] + tm.duration(t, robots[t]) for t in range(n)]
    previous: list[Previous] = [()] * n
    order = sorted(range(n), key=lambda t: (starts[t], ends[t], t))
    last: dict[int, int] = {}
    for t in order:
        mine = []
        for r in teams.get(t) or (robots[t],):
            q = last.get(r)
            zone_from = tm.robot_zone[r] if q is None else tm.task_zone[q]
            mine.append((r, q, tm.travel_to_task(zone_from, t)))
            last[r] = t
        previous[t] = tuple(mine)
    slots = tuple(
        Slot(
            task=t,
            robot=robots[t],
            start=float(starts[t]),
            end=float(ends[t]),
            zone=None if tm.task_zone[t] is None else tm.zones[tm.task_zone[t]],  # type: ignore[index]
            travel=previous[t][0][2],
            team=tuple(teams.get(t) or ()),
            team_travel=tuple(m for _, _, m in previous[t]) if teams.get(t) else (),
        )
        for t in range(n)
    )
    makespan = max((s.end for s in slots), default=0.0)
    return Schedule(
        slots=slots,
        makespan=makespan,
        robot_time=_robot_time(problem, slots, makespan),
        critical_path=_critical_path(problem, slots, previous),
        start=tm.start,
    )


def _robot_time(problem: Problem, slots: Sequence[Slot], makespan: float) -> tuple[RobotTime, ...]:
    tm = problem.instance.timing
    busy = [0.0] * tm.n_robots
    moved = [0.0] * tm.n_robots
    for s in slots:
        for r in s.members:
            busy[r] += s.end - s.start
            moved[r] += s.travel_of(r)
    out = []
    for r, (a, b) in enumerate(tm.shifts):
        window = max(0.0, min(b, makespan) - a)
        out.append(RobotTime(busy[r], max(0.0, window - busy[r] - moved[r]), moved[r]))
    return tuple(out)


def _critical_path(
    problem: Problem, slots: Sequence[Slot], previous: Sequence[Previous]
) -> tuple[Step, ...]:
    if not slots:
        return ()
    steps: list[Step] = []
    t: int | None = max(range(len(slots)), key=lambda k: (slots[k].end, -k))
    seen: set[int] = set()
    # A lead can explain a task by one that starts after it (docs/schedules.md#links),
    # so the walk stops at a task it has passed already.
    while t is not None and t not in seen:
        seen.add(t)
        s = slots[t]
        steps.append(Step(StepKind.TASK, s.start, s.end, t, s.robot, "works"))
        t = _explain_start(problem, slots, previous, t, steps)
    steps.reverse()
    if steps and steps[0].start > EPS:
        steps.insert(0, Step(StepKind.WAIT, 0.0, steps[0].start, steps[0].task, None, "plan start"))
    return tuple(steps)


def _explain_start(
    problem: Problem,
    slots: Sequence[Slot],
    previous: Sequence[Previous],
    t: int,
    steps: list[Step],
) -> int | None:
    """Append the steps before task t's start (in reverse) and return the task the chain
    continues from, or None where it starts at a fixed time. A team task starts when its
    last member can begin: the member whose way there binds explains it."""
    tm = problem.instance.timing
    s = slots[t]
    if t in problem.pinned_starts:
        steps.append(Step(StepKind.WAIT, 0.0, s.start, t, s.robot, "pinned start"))
        return None
    # What each link lets the task start at (docs/schedules.md#links): a binding one explains it.
    allowed = _link_starts(tm, slots, t)
    for at, p in allowed:
        if abs(at - s.start) <= EPS:
            return p
    for r, q, travel in previous[t]:
        ready = (slots[q].end if q is not None else tm.shifts[r][0]) + travel
        if abs(ready - s.start) > EPS:
            continue
        if travel > 0:
            steps.append(Step(StepKind.TRAVEL, s.start - travel, s.start, t, r, "travel"))
        if q is not None:
            return q
        shift_start = tm.shifts[r][0]
        if shift_start > EPS:
            steps.append(Step(StepKind.WAIT, 0.0, shift_start, t, r, "shift start"))
        return None
    # A wait: the latest of release and not_before, else slack left by the solver.
    bounds = [
        (tm.release[t], "release"),
        (problem.not_before, "not before"),
    ]
    limit, cause = max(bounds, key=lambda b: b[0])
    if abs(limit - s.start) <= EPS:
        steps.append(Step(StepKind.WAIT, 0.0, s.start, t, s.robot, cause))
        return None
    # Nothing binds: the solver left slack. The latest of the other causes explains the rest.
    ends: list[tuple[float, int, int | None, float]] = [(at, p, None, 0.0) for at, p in allowed]
    ends += [(slots[q].end + m, q, r, m) for r, q, m in previous[t] if q is not None]
    if not ends or max(e[0] for e in ends) < limit:
        steps.append(Step(StepKind.WAIT, 0.0, s.start, t, s.robot, "slack"))
        return None
    when, via, member, travel = max(ends, key=lambda e: (e[0], e[1]))
    steps.append(Step(StepKind.WAIT, when, s.start, t, s.robot, "slack"))
    if member is not None and travel > 0:
        steps.append(Step(StepKind.TRAVEL, when - travel, when, t, member, "travel"))
    return via


def _link_starts(tm: TimeModel, slots: Sequence[Slot], t: int) -> list[tuple[float, int]]:
    """(the start each of task t's links allows, its predecessor)."""
    d = slots[t].end - slots[t].start
    return [
        (allowed_start(a, d, slots[a.pred].start, slots[a.pred].end), a.pred) for a in tm.links[t]
    ]
