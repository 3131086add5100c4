"""The graph's view of time on a timed instance (docs/schedules.md#runs-in-time): which task comes
next and what each robot would make of it, from the robots' timelines as decided so far.

The timelines grow with the run, so they live here, in the run-scoped context, never in
the checkpointed state (which stays O(robots)). They are a deterministic function of the
problem and the stored decisions (app.domain.scheduling.progress), so a process that
resumes a run, or re-runs a node, rebuilds them from the recorder and finds the same.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from app.domain.decision import DecisionContext, Members, percent
from app.domain.problem import Problem
from app.domain.scheduling.progress import TimedProgress, TimeOption
from app.graph.recorder import DecisionRecord, Recorder


@dataclass
class TimedCursor:
    """The run's TimedProgress, positioned at the task the graph is deciding."""

    progress: TimedProgress | None = None

    def at(self, problem: Problem, recorder: Recorder, task: int) -> TimedProgress:
        """The progress with every decision before `task` placed and `task` next (or placed
        already: store_and_route re-run in the same process). Rebuilt from the recorder on
        first use in a process and whenever it disagrees with the graph's state."""
        progress = self.progress
        if progress is None or (task not in progress.placed and progress.current() != task):
            decisions = recorder.decisions()
            robots = {d.task_index: d.robot for d in decisions}
            teams = decision_teams(problem, decisions)
            progress = TimedProgress.replay(problem, robots, until=task, teams=teams)
            self.progress = progress
        return progress


def decision_teams(problem: Problem, decisions: Sequence[DecisionRecord]) -> dict[int, Members]:
    """Task index -> its members in unit order, for the stored team decisions."""
    index = {r.name: i for i, r in enumerate(problem.instance.robots)}
    return {d.task_index: tuple(index[m["robot"]] for m in d.team) for d in decisions if d.team}


def first_task(problem: Problem) -> int:
    """The first task a timed run decides."""
    return TimedProgress(problem).current()


def options_for(
    cursor: TimedCursor, problem: Problem, recorder: Recorder, task: int
) -> tuple[TimeOption, ...]:
    return cursor.at(problem, recorder, task).options(task)


def best_in_time(dctx: DecisionContext) -> int:
    """The fallback on a timed instance (docs/schedules.md#validation-in-time): among the robots
    allowed (the cap, the deadline and the shift), the one with the best success; ties: the earlier
    end, then fleet order."""
    return min(dctx.feasible, key=lambda r: (-dctx.success[r], dctx.timing[r].end, r))


def fallback_answer(dctx: DecisionContext, robot: int) -> str:
    """The fallback's answer in the required format, so it is validated like any other."""
    labels, s, loads = dctx.labels, dctx.success, dctx.loads
    o = dctx.timing[robot]
    fewest = min(dctx.feasible, key=lambda r: (loads[r], -s[r], r))
    gap = (s[robot] - s[fewest]) * 100
    after = ", ".join(
        f"{labels[r]}: {loads[r] + (1 if r == robot else 0)}" for r in range(len(labels))
    )
    return "\n".join(
        [
            f"**Decision**: {labels[robot]}",
            f"**Expected Success**: {percent(s[robot])}",
            f"**Reasoning**: Fallback after the attempts failed: {labels[robot]} has the best "
            f"success, {percent(s[robot])}, of the robots that keep the workload cap and meet "
            f"the task's deadline and their shift. It would start at minute {o.start:g} and "
            f"end at {o.end:g} in the {dctx.phase.value} phase.",
            f"**Workload After Assignment**: {after}",
            "**Confidence Level**: Low",
            f"**Trade-Off Summary**: best {labels[robot]} {percent(s[robot])} vs least-loaded "
            f"{labels[fewest]} {percent(s[fewest])} ({loads[fewest]} tasks): gap {gap:.1f} "
            f"points; the fallback takes the best success in time.",
        ]
    )


def time_record(
    dctx: DecisionContext, robot: int, seq: int, team: Members | None = None
) -> dict[str, Any]:
    """What a decision records in time: start, end, zone, travel, its place in the order,
    and the trade-off in minutes (how much later it ends than the earliest end among the
    robots that were allowed; a team: than the earlier of the two candidate teams')."""
    facts = dctx.team
    if team is not None and facts is not None and facts.timing is not None:
        # docs/allocation.md#teams: the team's start is its last member's arrival; `travel`
        # is the first member's, as the team's `robot` is.
        timed = facts.timing
        o = timed(team)
        rivals = [timed(m).end for m in (facts.best, facts.fewest) if m is not None]
        return {
            "start": o.start,
            "end": o.end,
            "zone": dctx.zone,
            "travel": dctx.timing[robot].travel,
            "seq": seq,
            "later_by": max(0.0, o.end - min(rivals, default=o.end)),
        }
    o = dctx.timing[robot]
    earliest = min(dctx.timing[r].end for r in dctx.feasible)
    return {
        "start": o.start,
        "end": o.end,
        "zone": dctx.zone,
        "travel": o.travel,
        "seq": seq,
        "later_by": max(0.0, o.end - earliest),
    }
