"""A plan re-timed by what the site reported (docs/living-plans.md#the-runs-current-schedule).

Execution reports with times are the truth: a task reported started sits at its reported
start, a task reported done (or failed) ends at its reported time, and a task that ran
late pushes what follows it. A run that is not revised keeps its decisions, so its
schedule view changes only in time: the reported tasks sit at their reported times, and
every robot keeps its other tasks in the order it was given, each as early as its
predecessors, its robot (plus travel), its release allow. An unreported task planned
before a reported one stays before it where it fits in the time before it (the site may
not have reported it yet), else it goes after it (the list scheduler's rule for fixed
tasks, `list_schedule.Timeline`); a task planned after a reported one stays after it.

The view depends on the decisions and the reports only, never on the clock: an unstarted
task may still show a start in the past (nothing reported it late yet). A revision is
what moves the unstarted work past `now` (`Problem.not_before`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime

from app.domain.problem import Problem
from app.domain.scheduling.list_schedule import Timeline, team_start
from app.domain.scheduling.schedule import Schedule, build_schedule
from app.domain.time_model import TimeModel

# A task reported done at the very instant it was reported started ran for no measurable
# time; a duration is positive (docs/schedules.md#the-model), so it counts as one second.
MIN_MINUTES = 1 / 60


@dataclass(frozen=True)
class Reported:
    """What the site said of one task, in minutes of the plan: when it started (None: no
    start was reported) and when it ended (done or failed; None: still running)."""

    start: float | None
    end: float | None = None


def minutes_since(origin: datetime, at: datetime) -> float:
    """Minutes from the plan's minute 0 (`origin`, aware) to an aware time."""
    return (at - origin).total_seconds() / 60.0


def reported_interval(reported: Reported, planned_minutes: float) -> tuple[float, float]:
    """(start, end) of a reported task: a missing start is its end less the planned
    duration; a missing end is its start plus the planned duration. Never before minute 0
    (a start reported before the plan's start counts from minute 0)."""
    if reported.start is None and reported.end is None:
        raise ValueError("a reported task has a start or an end")
    if reported.start is None:
        assert reported.end is not None
        start = max(0.0, reported.end - planned_minutes)
    else:
        start = max(0.0, reported.start)
    end = start + planned_minutes if reported.end is None else max(reported.end, start)
    return start, max(end, start + MIN_MINUTES)


def retime(problem: Problem, planned: Schedule, reported: Mapping[int, Reported]) -> Schedule:
    """The planned schedule with the reported tasks at their reported times and every other
    task re-timed as early as the rules allow, each robot keeping its tasks and order.

    Reported tasks are facts (as pinned starts are): they wait for nothing, and their ends
    may differ from the planned durations (`check_schedule` then names the difference
    under `duration`)."""
    tm = problem.instance.timing
    n = tm.n_tasks
    robots = planned.assignment
    # docs/allocation.md#teams: a team task holds every member's lane and starts when the
    # last member can begin (list_schedule.team_start), whether a fact or re-timed.
    teams = {s.task: s.team for s in planned.slots if s.team}
    fixed: dict[int, tuple[float, float]] = {}
    for t, report in reported.items():
        if 0 <= t < n:
            fixed[t] = reported_interval(report, tm.duration(t, robots[t]))
    for t, start in problem.pinned_starts.items():
        if t not in fixed:
            fixed[t] = (start, start + tm.duration(t, robots[t]))
    starts = [0.0] * n
    ends = [0.0] * n
    done = [False] * n
    lines = [Timeline(a, tm.robot_zone[r]) for r, (a, _) in enumerate(tm.shifts)]
    for t, (start, end) in sorted(fixed.items(), key=lambda item: item[1]):
        for m in teams.get(t) or (robots[t],):
            lines[m].fixed.append((start, end, t))
        starts[t], ends[t], done[t] = start, end, True
    orders = planned.sequences(tm.n_robots)
    positions = [{t: k for k, t in enumerate(seq)} for seq in orders]
    queues = [[t for t in seq if t not in fixed] for seq in orders]
    cursor = [0] * len(queues)

    def at_front(t: int, crew: tuple[int, ...]) -> bool:
        return all(cursor[m] < len(queues[m]) and queues[m][cursor[m]] == t for m in crew)

    progress = True
    forced = False
    while progress:
        progress = False
        for r, queue in enumerate(queues):
            while cursor[r] < len(queue):
                t = queue[cursor[r]]
                if not all(done[p] for p in tm.predecessors[t]) and not forced:
                    break
                crew = teams.get(t) or (r,)
                if not at_front(t, crew):
                    break  # a member has earlier tasks to do first
                forced = False
                ready = tm.ready(t, tm.duration(t, r), starts, ends)
                ready = max(ready, tm.release[t], problem.not_before)
                for m in crew:
                    _pass_earlier_facts(tm, lines[m], positions[m], t)
                if len(crew) == 1:
                    start = lines[r].earliest(tm, t, r, ready)
                else:
                    start = team_start(lines, tm, t, crew, ready)
                for m in crew:
                    lines[m].place(tm, t, m, start)
                    cursor[m] += 1
                starts[t], ends[t], done[t] = start, start + tm.duration(t, r), True
                progress = True
        if not progress and tm.typed and not all(done) and not forced:
            # A lead let the plan put a successor before its predecessor on one robot:
            # the first robot's next task goes now, with the links placed so far, so the
            # view keeps the order and the check names any link it breaks (once per stall:
            # a team whose members disagree on what comes next is not a lead).
            forced = progress = True
    if not all(done):
        # Only when the planned orders contradict the precedence: facts wait for nothing.
        raise ValueError("the robot orders contradict the precedence: no task can go next")
    return build_schedule(problem, robots, starts, ends, teams)


def _pass_earlier_facts(tm: TimeModel, line: Timeline, position: Mapping[int, int], t: int) -> None:
    """The robot's reported tasks planned before `t` come before it, whenever they ran: a
    task planned after one does not slip into a gap before it (the order is kept)."""
    ahead = sorted((f for f in line.fixed if position[f[2]] < position[t]), key=lambda f: f[1])
    for fact in ahead:
        line.fixed.remove(fact)
        line.free, line.zone = max(line.free, fact[1]), tm.task_zone[fact[2]]
