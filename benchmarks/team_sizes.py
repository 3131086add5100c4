"""Team instances by size (issue 30, point 7): the exact methods against `greedy` and the
LTAA graph, unguided and guided, on the expected success, the makespan and the time per
decision (docs/allocation.md#teams, docs/schedules.md#teams-in-time).

    python -m benchmarks.team_sizes [--sizes 36x3,60x5,100x5,200x10] [--seeds 0]

Instances: the seeded construction site of `benchmarks/timed_instances.py` (floors x zones x
trades, travel between zones, shifts) where every pour needs two robots covering `heavy` and
every formwork one `heavy` and one `careful` (each member busy for the mean of the task's
per-robot minutes). The untimed twin is the same tasks and robots without durations, zones,
precedence or shifts. Mode balanced (the cap on unit loads).

- Untimed: `optimal` (the min-cost flow over units: the exact ES), `greedy`, `ltaa` (rules
  reasoner) unguided and guided by the optimizer. ES regret = optimal's ES minus the
  method's, in points of expected success.
- Timed: `optimal` and `greedy` timed by the list scheduler, `schedule` (the multi-skill
  CP-SAT model, objective success then makespan, `time_limit_s` as given: a deterministic
  budget) and `ltaa` unguided and guided. Makespan regret = the method's makespan over the
  best any method found on the instance, minus 1 (a lower bound on the true regret; the
  `schedule` row's bound says how far the best can be from the optimum).

A method that refuses an instance (the LTAA graph refuses timed team tasks until its time
lines place teams; `schedule` refuses a team model past its size limit) gets a row saying
so with its sentence, not a failure: once `ltaa` accepts timed team instances its timed rows
come in by themselves on the next run.

CPU seconds of this process (`time.process_time`) per call; per decision = per task. The
section is its own (`benchmarks.common.write_section`); `make bench` runs it too.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from app.domain.errors import DomainError
from app.domain.metrics import expected_success
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.solvers.base import Solution
from app.solvers.cpsat.search import solve_schedule
from app.solvers.registry import get_solver
from benchmarks.common import IMG, Section, machine, table, write_section
from benchmarks.timed_instances import construction_site

TITLE = "Teams by size: exact, greedy and LTAA"
HEADING = f"## {TITLE}"
SIZES = ((36, 3), (60, 5), (100, 5), (200, 10))
SEEDS = (0,)
TIME_LIMIT_S = 10.0
TEAMS = {"pour": {"heavy": 2}, "formwork": {"heavy": 1, "careful": 1}}
IMAGE = "team_sizes.png"
WALL_CAP_S = 900.0


@dataclass(frozen=True)
class Method:
    label: str
    solver: str
    options: dict[str, Any]
    makespan_only: bool = False  # objective `makespan` with no ES floor (else the default)


UNTIMED = (
    Method("optimal", "optimal", {}),
    Method("greedy", "greedy", {}),
    Method("LTAA unguided", "ltaa", {}),
    Method("LTAA guided", "ltaa", {"guidance": "optimizer"}),
)
# `schedule`'s budget is filled in by `methods_timed`.
TIMED = (
    Method("optimal + list schedule", "optimal", {}),
    Method("greedy", "greedy", {}),
    Method("schedule", "schedule", {}),
    Method("schedule, makespan", "schedule", {}, makespan_only=True),
    Method("LTAA unguided", "ltaa", {}),
    Method("LTAA guided", "ltaa", {"guidance": "optimizer"}),
)


def team_site(n_tasks: int, n_robots: int, *, seed: int = 0, timed: bool = True) -> Instance:
    """The construction site of `timed_instances` with its pours and formworks as teams
    (TEAMS); untimed: the same tasks and robots without any time field."""
    site = construction_site(n_tasks, n_robots, seed=seed)
    tasks = []
    for task in site.tasks:
        team = TEAMS.get(task.type)
        if team is not None:
            minutes = task.duration.values() if isinstance(task.duration, dict) else ()
            task = replace(
                task,
                features=tuple(team),
                team=dict(team),
                duration=float(round(statistics.fmean(minutes))) if minutes else task.duration,
            )
        if not timed:
            task = Task(
                id=task.id, name=task.name, features=task.features, type=task.type, team=task.team
            )
        tasks.append(task)
    if timed:
        return Instance(tasks=tuple(tasks), robots=site.robots, travel=site.travel, start=None)
    robots = tuple(Robot(name=r.name, success=r.success, label=r.label) for r in site.robots)
    return Instance(tasks=tuple(tasks), robots=robots)


def _solve(problem: Problem, method: Method) -> Solution:
    """The method's answer. `schedule` as `app/solvers/schedule.py` runs it, with the
    wall-clock net widened (as in the MSPSP and Brandimarte benchmarks): the figures are
    the deterministic budget's, not the machine's load."""
    if method.solver != "schedule":
        return get_solver(method.solver).solve(problem, options=method.options)
    get_solver("schedule").check_supported(problem)
    limit = float(method.options.get("time_limit_s", TIME_LIMIT_S))
    outcome = solve_schedule(problem, time_limit_s=limit, wall_cap_s=WALL_CAP_S)
    return Solution(
        outcome.schedule.assignment, details=outcome.details(), teams=outcome.schedule.teams
    )


def measure_one(problem: Problem, method: Method) -> dict[str, Any]:
    """One call: ES, makespan (timed), status, bound, CPU; or the refusal's sentence."""
    if method.makespan_only:
        problem = Problem.build(
            problem.instance, problem.mode, objective=Objective(ObjectiveKind.MAKESPAN, 0.0)
        )
    started = time.process_time()
    try:
        solution = _solve(problem, method)
    except DomainError as exc:
        return {"method": method.label, "refused": exc.message, "code": exc.code}
    cpu = time.process_time() - started
    details = solution.details
    row: dict[str, Any] = {
        "method": method.label,
        "es": expected_success(problem.instance, solution.assignment, solution.teams),
        "cpu_s": cpu,
        "per_decision_ms": 1000 * cpu / problem.instance.n_tasks,
        "status": details.get("status", ""),
    }
    schedule = details.get("schedule")
    if schedule is not None:
        row["makespan"] = float(schedule.makespan)
        row["broken"] = len(check_schedule(problem, schedule))
        if details.get("bound") is not None:
            row["bound"] = float(details["bound"])
        row["wall_cut"] = bool(details.get("budget", {}).get("wall_cut", False))
    elif problem.instance.timed:
        row["refused"] = f"no schedule: {details.get('schedule_error', 'none attached')}"
    if method.solver == "ltaa":
        row["fallbacks"] = details.get("fallbacks", 0)
    return row


def methods_timed(time_limit_s: float) -> tuple[Method, ...]:
    return tuple(
        replace(m, label=f"{m.label} ({time_limit_s:g} s)", options={"time_limit_s": time_limit_s})
        if m.solver == "schedule"
        else m
        for m in TIMED
    )


def measure(
    sizes: tuple[tuple[int, int], ...] = SIZES,
    seeds: tuple[int, ...] = SEEDS,
    time_limit_s: float = TIME_LIMIT_S,
) -> list[dict[str, Any]]:
    """One row per (size, seed, timed or not, method), with the regrets filled in."""
    _warm_up()
    rows: list[dict[str, Any]] = []
    for n_tasks, n_robots in sizes:
        for seed in seeds:
            for timed, methods in ((False, UNTIMED), (True, methods_timed(time_limit_s))):
                instance = team_site(n_tasks, n_robots, seed=seed, timed=timed)
                problem = Problem.build(instance, Mode.BALANCED)
                found = [measure_one(problem, m) for m in methods]
                _regrets(found)
                for row in found:
                    row.update(
                        size=f"{n_tasks} x {n_robots}",
                        seed=seed,
                        timed=timed,
                        units=sum(instance.loads_added),
                    )
                    print(f"{row}", file=sys.stderr)
                rows.extend(found)
    return rows


def _warm_up() -> None:
    """Every method once on a tiny instance: imports and first-call costs out of the
    measurements."""
    for timed, methods in ((False, UNTIMED), (True, methods_timed(0.1))):
        problem = Problem.build(team_site(8, 3, timed=timed), Mode.BALANCED)
        for method in methods:
            measure_one(problem, method)


def _regrets(rows: list[dict[str, Any]]) -> None:
    """ES regret against the exact optimum (the first row's, `optimal`), makespan regret
    against the best makespan of the instance's rows."""
    exact = rows[0].get("es")
    spans = [r["makespan"] for r in rows if "makespan" in r and not r.get("broken")]
    best = min(spans, default=None)
    for r in rows:
        if "es" in r and exact is not None:
            r["es_regret"] = max(0.0, exact - r["es"])
        if "makespan" in r and best:
            r["makespan_regret"] = r["makespan"] / best - 1.0


# -- the section ---------------------------------------------------------------------------


def _cell(row: dict[str, Any], key: str, fmt: str) -> str:
    return "" if row.get(key) is None else format(row[key], fmt)


def _refusals(rows: list[dict[str, Any]]) -> list[str]:
    """Each refusal's sentence once, in order: the table cites them by number."""
    return list(dict.fromkeys(r["refused"] for r in rows if "refused" in r))


def _table_rows(rows: list[dict[str, Any]], timed: bool) -> list[tuple[Any, ...]]:
    out, notes = [], _refusals(rows)
    for r in rows:
        if r["timed"] != timed:
            continue
        head = (r["size"], r["seed"], r["method"])
        if "refused" in r:
            cell = f"refused ({notes.index(r['refused']) + 1})"
            out.append((*head, cell, *("",) * (7 if timed else 3)))
            continue
        cells = [
            _cell(r, "es", ".4f"),
            f"{100 * r.get('es_regret', 0.0):.2f}",
        ]
        if timed:
            bound = _cell(r, "bound", "g")
            status = r["status"] + (" (wall cut)" if r.get("wall_cut") else "")
            cells += [
                _cell(r, "makespan", "g"),
                f"{100 * r['makespan_regret']:.1f}%" if "makespan_regret" in r else "",
                f"{status} {bound}".strip(),
                str(r.get("broken", "")),
            ]
        cells += [f"{r['cpu_s']:.2f}", f"{r['per_decision_ms']:.1f}"]
        out.append((*head, *cells))
    return out


def body(rows: list[dict[str, Any]], image: str | None, time_limit_s: float) -> str:
    lines = [
        "`python -m benchmarks.team_sizes`: the seeded construction site of "
        "`benchmarks/timed_instances.py` with every pour a team of two `heavy` and every "
        "formwork one `heavy` and one `careful` (docs/allocation.md#teams), mode balanced. "
        "Untimed: the same tasks and robots without time. ES regret: `optimal`'s ES minus "
        "the method's, in points; makespan regret: over the best makespan any method found "
        f"on the instance (a lower bound on the true regret). `schedule`: the multi-skill "
        f"CP-SAT model, {time_limit_s:g} s deterministic budget, one worker (status and "
        "bound), with the default objective (the best ES, then the shortest makespan at it) "
        "and with `makespan` alone (no ES floor: its bound holds for every plan under the "
        "cap, so the true makespan regret of a row is at most its makespan over that bound). "
        "LTAA: the rules reasoner, "
        "guided = `guidance: optimizer`. CPU seconds of the call; per decision = per task. "
        f"Machine: {machine()}.",
        "",
        "**Untimed team instances (expected success):**",
        "",
        table(
            ["size", "seed", "method", "ES", "ES regret (pts)", "CPU s", "ms / decision"],
            _table_rows(rows, timed=False),
        ),
        "",
        "**Timed team instances (makespan, minutes):**",
        "",
        table(
            [
                "size",
                "seed",
                "method",
                "ES",
                "ES regret (pts)",
                "makespan",
                "makespan regret",
                "status, bound",
                "broken",
                "CPU s",
                "ms / decision",
            ],
            _table_rows(rows, timed=True),
        ),
        "",
    ]
    lines += [f"({i}) {sentence}" + "  " for i, sentence in enumerate(_refusals(rows), 1)]
    if any(r["method"].startswith("LTAA") and "refused" in r for r in rows):
        lines += [
            "",
            "The LTAA rows on timed team instances come in by themselves once the graph "
            "schedules timed team tasks: re-run `python -m benchmarks.team_sizes` (or `ltaa "
            "bench benchmarks.team_sizes`); a refusal is a row with its sentence, never a "
            "failure of the benchmark.",
        ]
    lines.append("")
    if image:
        lines += [f"![ES regret and CPU per decision by size]({image})", ""]
    return "\n".join(lines)


def figure(rows: list[dict[str, Any]], directory: Path = IMG) -> str:
    """ES regret (untimed) and CPU per decision (both) against the number of tasks."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from benchmarks.plots import PALETTE, save

    fig, (left, right) = plt.subplots(1, 2, figsize=(9.0, 3.6))
    labels = list(dict.fromkeys(r["method"] for r in rows))
    for i, label in enumerate(labels):
        colour = PALETTE[i % len(PALETTE)]
        for timed, style in ((False, "-"), (True, "--")):
            mine = [r for r in rows if r["method"] == label and r["timed"] == timed]
            mine = [r for r in mine if "refused" not in r]
            if not mine:
                continue
            xs = [int(r["size"].split(" x ")[0]) for r in mine]
            tag = f"{label} ({'timed' if timed else 'untimed'})"
            right.plot(
                xs, [r["per_decision_ms"] for r in mine], style, marker="o", color=colour, label=tag
            )
            if not timed:
                left.plot(
                    xs,
                    [100 * r["es_regret"] for r in mine],
                    style,
                    marker="o",
                    color=colour,
                    label=label,
                )
    left.set_xlabel("tasks")
    left.set_ylabel("ES regret vs optimal (points)")
    left.set_title("Untimed team instances")
    left.legend(fontsize=7, title="(optimal and guided: 0)", title_fontsize=7)
    right.set_xlabel("tasks")
    right.set_ylabel("CPU ms per decision")
    right.set_yscale("log")
    right.set_title("Time per decision")
    # beside the axes: inside, the legend hid the slowest points
    right.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False)
    return save(fig, IMAGE, directory)


def section(
    sizes: tuple[tuple[int, int], ...] = SIZES,
    seeds: tuple[int, ...] = SEEDS,
    time_limit_s: float = TIME_LIMIT_S,
    *,
    draw: bool = True,
) -> str:
    rows = measure(sizes, seeds, time_limit_s)
    image = figure(rows) if draw and rows else None
    return f"{HEADING}\n\n{body(rows, image, time_limit_s)}"


def run() -> Section:
    """For `make bench` (benchmarks/report.py)."""
    text = section()
    return Section(TITLE, text.removeprefix(f"{HEADING}\n\n"), [f"img/{IMAGE}"])


def _sizes(text: str) -> tuple[tuple[int, int], ...]:
    out = []
    for part in text.split(","):
        n, m = part.lower().split("x")
        out.append((int(n), int(m)))
    return tuple(out)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.team_sizes")
    parser.add_argument("--sizes", default=",".join(f"{n}x{m}" for n, m in SIZES))
    parser.add_argument("--seeds", default=",".join(str(s) for s in SEEDS))
    parser.add_argument("--time-limit", type=float, default=TIME_LIMIT_S)
    args = parser.parse_args(argv)
    seeds = tuple(int(s) for s in args.seeds.split(","))
    text = section(_sizes(args.sizes), seeds, args.time_limit)
    write_section(HEADING, text)
    print(text)


if __name__ == "__main__":
    main(sys.argv[1:])
