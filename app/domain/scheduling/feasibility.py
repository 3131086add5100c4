"""Is a schedule feasible? The one check that every solver and test uses
(docs/schedules.md#a-schedule-and-its-check).

It reads only the decision (robot, start, end per task) and recomputes everything else
from the problem, so a schedule's own derived fields (travel, zone) cannot vouch for
themselves. Every broken rule is reported, each as a Violation naming the rule, the task
and the robot, with a sentence a supervisor can act on; an empty list means feasible.

A task with a pinned start (reported started or done) is a fact: its own release,
deadline, shift, links and (as a robot's first task) the way from the start zone
are not held against the plan; the plan must keep it at its start, on its robot, and fit
everything else around it (overlap, travel to and from it, successors).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from app.domain.links import broken, gap
from app.domain.metrics import workload
from app.domain.problem import Problem
from app.domain.scheduling.schedule import EPS, Schedule, Slot
from app.domain.teams import team_problem


class Rule(StrEnum):
    COMPLETE = "complete"  # one slot per task, in queue order
    ELIGIBILITY = "eligibility"  # the robot may take the task (its duration map names it)
    DURATION = "duration"  # end - start is the robot's duration for the task
    PRECEDENCE = "precedence"  # each link of docs/schedules.md#links holds (FS: start after end)
    OVERLAP = "overlap"  # a robot does one task at a time
    TRAVEL = "travel"  # ... and travels between zones in between (from its start zone)
    RELEASE = "release"
    DEADLINE = "deadline"
    SHIFT = "shift"
    NOT_BEFORE = "not_before"  # nothing without a fixed start begins before `not_before`
    PIN = "pin"  # pinned tasks keep their robot and, when fixed, their start
    UNAVAILABLE = "unavailable"  # an unavailable robot takes no new task
    CAP = "cap"  # the workload cap of docs/allocation.md#the-workload-cap (loads count tasks)
    TEAM = "team"  # every unit of a team task covered by a distinct robot able to cover it


@dataclass(frozen=True)
class Violation:
    rule: Rule
    message: str
    task: int | None = None  # task index
    robot: int | None = None  # robot index


def check_schedule(problem: Problem, schedule: Schedule) -> list[Violation]:
    instance = problem.instance
    tm = instance.timing
    slots = schedule.slots
    if len(slots) != tm.n_tasks or [s.task for s in slots] != list(range(tm.n_tasks)):
        return [
            Violation(
                Rule.COMPLETE,
                f"the schedule must place each of the {tm.n_tasks} tasks once, in queue order",
            )
        ]
    out: list[Violation] = []
    tasks, robots = instance.tasks, instance.robots
    starts, ends = [s.start for s in slots], [s.end for s in slots]

    def task(t: int) -> str:
        return f"task {tasks[t].id!r} ({tasks[t].name})"

    def add(rule: Rule, message: str, t: int | None = None, r: int | None = None) -> None:
        out.append(Violation(rule, message, t, r))

    for s in slots:
        t, r = s.task, s.robot
        if not all(0 <= m < tm.n_robots for m in s.members):
            add(Rule.COMPLETE, f"{task(t)} is on robot index {r}, outside the fleet", t)
            continue
        name = robots[r].name
        out.extend(_member_rules(problem, s))
        fixed = problem.pinned_starts.get(t)  # a fact (see the module docstring)
        if fixed is None and s.start < tm.release[t] - EPS:
            add(
                Rule.RELEASE,
                f"{task(t)} starts at {s.start:g}, before its release {tm.release[t]:g}",
                t,
                r,
            )
        if fixed is None and s.end > tm.deadline[t] + EPS:
            add(
                Rule.DEADLINE,
                f"{task(t)} ends at {s.end:g}, after its deadline {tm.deadline[t]:g}",
                t,
                r,
            )
        if fixed is None and s.start < problem.not_before - EPS:
            add(
                Rule.NOT_BEFORE,
                f"{task(t)} starts at {s.start:g}, before minute {problem.not_before:g} (now)",
                t,
                r,
            )
        pin = problem.pinned.get(t)
        if pin is not None and pin != r:
            add(Rule.PIN, f"{task(t)} is pinned on '{robots[pin].name}' but runs on '{name}'", t, r)
        team = problem.pinned_teams.get(t)
        if team is not None and tuple(s.members) != team:
            pinned = " + ".join(robots[m].name for m in team)
            add(Rule.PIN, f"{task(t)} is pinned on the team {pinned}, not the one it runs on", t, r)
        if fixed is not None and abs(s.start - fixed) > EPS:
            add(
                Rule.PIN,
                f"{task(t)} must start at its pinned start {fixed:g}, not {s.start:g}",
                t,
                r,
            )
        for arc in tm.links[t] if fixed is None else ():
            if gap(arc, s.start, s.end, starts, ends) < -EPS:
                said = broken(arc, (s.start, s.end), starts, ends, task(arc.pred))
                add(Rule.PRECEDENCE, f"{task(t)} {said}", t, r)
    out.extend(_check_robots(problem, schedule))
    placed = [s for s in slots if all(0 <= m < tm.n_robots for m in s.members)]
    loads = workload(
        [s.robot for s in placed], tm.n_robots, {s.task: s.team for s in placed if s.team}
    )
    if not problem.cap.respected_by(loads):
        lo, hi = problem.cap.lower, problem.cap.upper
        add(Rule.CAP, f"loads {loads} break the workload cap: each robot needs {lo} to {hi} tasks")
    return out


def _check_robots(problem: Problem, schedule: Schedule) -> list[Violation]:
    """One task at a time per robot, with the travel between zones in between."""
    out: list[Violation] = []
    tm = problem.instance.timing
    tasks, robots = problem.instance.tasks, problem.instance.robots
    by_robot: list[list[int]] = [[] for _ in range(tm.n_robots)]
    for s in schedule.slots:
        for m in s.members:
            if 0 <= m < tm.n_robots:
                by_robot[m].append(s.task)
    for r, mine in enumerate(by_robot):
        mine.sort(key=lambda t: (schedule.slots[t].start, schedule.slots[t].end, t))
        name = robots[r].name
        free, zone, previous = tm.shifts[r][0], tm.robot_zone[r], None
        for t in mine:
            s = schedule.slots[t]
            label = f"task {tasks[t].id!r} ({tasks[t].name})"
            if previous is not None and s.start < schedule.slots[previous].end - EPS:
                other = tasks[previous].id
                message = f"'{name}' runs {label} while task {other!r} still runs"
                out.append(Violation(Rule.OVERLAP, message, t, r))
            else:
                move = tm.travel_to_task(zone, t)  # each member travels on its own way
                fact = previous is None and t in problem.pinned_starts  # it was there
                if move > 0 and not fact and s.start < free + move - EPS:
                    where = "its start zone" if previous is None else f"task {tasks[previous].id!r}"
                    message = (
                        f"'{name}' starts {label} at {s.start:g}, but needs {move:g} min to "
                        f"travel from {where} (free at {free:g})"
                    )
                    out.append(Violation(Rule.TRAVEL, message, t, r))
            free, zone, previous = max(free, s.end), tm.task_zone[t], t
    return out


def _member_rules(problem: Problem, s: Slot) -> list[Violation]:
    """The rules each robot on the task keeps: the team's coverage, eligibility, the
    duration, its shift, and no new task while unavailable (docs/allocation.md#teams)."""
    out: list[Violation] = []
    tm, tasks, robots = problem.instance.timing, problem.instance.tasks, problem.instance.robots
    t, r = s.task, s.robot
    fixed = problem.pinned_starts.get(t)
    pin = problem.pinned.get(t)

    def task(t: int) -> str:
        return f"task {tasks[t].id!r} ({tasks[t].name})"

    def add(rule: Rule, message: str, t: int | None = None, r: int | None = None) -> None:
        out.append(Violation(rule, message, t, r))

    why = _team_rule(problem, s)
    if why is not None:
        add(Rule.TEAM, f"{task(t)}: {why}", t, r)
    for m in s.members:
        d = tm.durations[t][m]
        if d is None:
            add(
                Rule.ELIGIBILITY,
                f"{task(t)} is on '{robots[m].name}', which cannot take it",
                t,
                m,
            )
        elif abs((s.end - s.start) - d) > EPS:
            add(
                Rule.DURATION,
                f"{task(t)} runs {s.end - s.start:g} min on '{robots[m].name}', which takes {d:g}",
                t,
                m,
            )
    for m in s.members:
        a, b = tm.shifts[m]
        if fixed is None and (s.start < a - EPS or s.end > b + EPS):
            add(
                Rule.SHIFT,
                f"{task(t)} runs [{s.start:g}, {s.end:g}], outside the shift "
                f"[{a:g}, {b:g}] of '{robots[m].name}'",
                t,
                m,
            )
    for m in s.members if pin is None else ():
        if m in problem.unavailable:
            off = robots[m].name
            add(Rule.UNAVAILABLE, f"{task(t)} is a new task on unavailable robot '{off}'", t, m)
    return out


def _team_rule(problem: Problem, slot: Slot) -> str | None:
    """Why the slot's robots do not cover its task as docs/allocation.md#teams asks, or None."""
    task = problem.instance.tasks[slot.task]
    if task.team is None:
        return None if not slot.team else "a single-robot task has a team"
    if not slot.team:
        return "a team task has no team"
    why = team_problem(task, problem.instance.robots, slot.team)
    if why is None and slot.team[0] != slot.robot:
        why = "its robot is not the member covering the first unit"
    return why
