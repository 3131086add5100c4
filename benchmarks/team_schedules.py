"""Teams in time on `baseline_team` (docs/schedules.md#the-team-scenario): every team method's
makespan, expected success and CPU time, and what `schedule` proves.

    python -m benchmarks.team_schedules          # writes its section of docs/benchmarks.md

Stand-alone, like the console and exchange benchmarks (`write_section` replaces only its
own section). CPU seconds of this process (`time.process_time`), not wall time: the machine
is shared, and CP-SAT's budget is deterministic anyway.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

from app.domain.catalog import timed_scenario
from app.domain.metrics import expected_success
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.solvers.registry import get_solver
from benchmarks.common import write_section

SECTION_TITLE = "## Teams in time: baseline_team"
METHODS = ("greedy", "dp", "optimal", "schedule")
MODES = (Mode.BALANCED, Mode.SUCCESS_FOCUSED)
TIME_LIMITS = (2.0, 10.0)


@dataclass(frozen=True)
class Row:
    mode: str
    method: str
    makespan: float
    es: float
    cpu_s: float
    broken: int
    status: str = ""
    bound: float | None = None


def measure(
    mode: Mode, method: str, time_limit_s: float | None = None, scenario: str = "baseline_team"
) -> Row:
    problem = Problem.build(timed_scenario(scenario).instance, mode)
    options = None if time_limit_s is None else {"time_limit_s": time_limit_s}
    started = time.process_time()
    solution = get_solver(method).solve(problem, options=options)
    cpu = time.process_time() - started
    details = solution.details
    schedule = details["schedule"]
    label = method if time_limit_s is None else f"{method} ({time_limit_s:g} s)"
    return Row(
        mode=mode.value,
        method=label,
        makespan=schedule.makespan,
        es=expected_success(problem.instance, solution.assignment, solution.teams),
        cpu_s=cpu,
        broken=len(check_schedule(problem, schedule)),
        status=details.get("status", ""),
        bound=details.get("bound"),
    )


def bench() -> str:
    get_solver("schedule")  # imports out of the first measurement
    rows: list[Row] = []
    for mode in MODES:
        for method in METHODS:
            limits: tuple[float | None, ...] = TIME_LIMITS if method == "schedule" else (None,)
            rows.extend(measure(mode, method, limit) for limit in limits)
    lines = [
        f"{SECTION_TITLE}\n",
        "`python -m benchmarks.team_schedules`: the 36 tasks of `baseline_timed` where seven "
        "need two robots at once (43 units on 3 robots; docs/schedules.md#the-team-scenario). "
        "Every method but `schedule` keeps its teams and is timed by the list scheduler; "
        "`schedule` is the multi-skill CP-SAT model (one worker, deterministic budget). "
        "CPU seconds of the call; `broken`: rules the schedule breaks (`check_schedule`).\n",
        "| mode | method | makespan (min) | ES | CPU s | broken | status | bound | gap |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        gap = "" if r.bound is None else f"{(r.makespan - r.bound) / r.makespan:.1%}"
        bound = "" if r.bound is None else f"{r.bound:g}"
        lines.append(
            f"| {r.mode} | {r.method} | {r.makespan:g} | {r.es:.4f} | {r.cpu_s:.2f} | "
            f"{r.broken} | {r.status} | {bound} | {gap} |"
        )
    load = os.getloadavg()[0]
    lines.append(f"\nThe 1-minute load average was {load:.1f} at the end (two shared cores).\n")
    return "\n".join(lines) + "\n"


def main() -> None:
    text = bench()
    write_section(SECTION_TITLE, text)
    print(text)


if __name__ == "__main__":
    main()
