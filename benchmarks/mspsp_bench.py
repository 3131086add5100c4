"""MSPSP-InstLib set 2c against its published optima (issue 30: `schedule` on team tasks).

    python -m benchmarks.mspsp_bench [--dir FOLDER] [--pattern GLOB] [--limit N]

Reads a local copy of MSPSP-InstLib (`--dir`, or $LTAA_MSPSP_DIR; not committed here: it
has no licence; docs/benchmarks.md says where to get it), turns each set 2c instance
matching `--pattern` (default all 91) into a timed team
instance (`benchmarks/mspsp.py`), solves it with the `schedule` method (objective
`makespan`, no workload cap, `time_limit_s` 30: a deterministic budget; the wall-clock
net widened to 900 s, as for Brandimarte, so a loaded machine does not cut it) and checks each
answer twice: with the app's own feasibility check and with `plan_problems`, which reads
the plan against the `.dzn` data alone. Beside it, the plain CP-SAT model of the MSPSP
(`benchmarks/mspsp_plain.py`) is the independent reference for the reading.

The section (its own, in docs/benchmarks.md, via `benchmarks.common.write_section`) holds
per instance: tasks (teams), robots, the published optimum, our makespan, bound, status,
proven or not, and time; and the acceptance line of issue 30: the published optimum
reached on every instance run, proven optimal on at least two thirds, never a false
"optimal" (status optimal with a makespan above the published optimum).
Without the local copy the section says so in one line and nothing is measured.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from app.domain.errors import DomainError
from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.solvers.base import Solution
from app.solvers.cpsat.common import WALL_CAP_EXTRA_S, WALL_CAP_FACTOR
from app.solvers.cpsat.search import solve_schedule
from app.solvers.registry import get_solver
from benchmarks.common import (
    Section,
    machine,
    revision,
    revision_line,
    stale_mark,
    table,
    write_section,
)
from benchmarks.mspsp import (
    ENV,
    RESULTS_2C,
    Project,
    Published,
    local_copy,
    plan_makespan,
    plan_problems,
    project_instance,
    published_output,
    published_plan,
    published_results,
    read_dzn,
    set_2c,
)
from benchmarks.mspsp_plain import cpu_figure, plain_line, plain_model

TITLE = "Multi-skill project scheduling: MSPSP-InstLib set 2c"
HEADING = f"## {TITLE}"
LIMIT_S = 30.0
PLAIN_LIMIT_S = 30.0
WALL_CAP_S = 900.0  # the benchmark measures the deterministic budget, not the safety net
PATTERN = "inst_set2c_*"
SOURCE = "https://github.com/youngkd/MSPSP-InstLib"


def problem_of(project: Project) -> Problem:
    """The makespan alone: success is flat (1.0 on every skill), no floor, no cap."""
    return Problem.build(
        project_instance(project),
        Mode.SUCCESS_FOCUSED,
        uncapped=True,
        objective=Objective(ObjectiveKind.MAKESPAN, 0.0),
    )


def plan_of(
    project: Project, problem: Problem, solution: Solution
) -> tuple[dict[int, float], dict[int, list[tuple[int, int]]], list[str]]:
    """The answer's schedule as starts and (resource, skill) members per activity, 0-based,
    for `plan_problems`: a slot's members cover its task's units in unit order (a one-robot
    task: its robot, its feature); the `wait<a>` robots are no resource. Also what
    disagrees between the schedule and the answer's assignment and teams."""
    instance = problem.instance
    schedule = solution.details["schedule"]
    starts: dict[int, float] = {}
    members: dict[int, list[tuple[int, int]]] = {}
    disagree: list[str] = []
    for slot in schedule.slots:
        task = instance.tasks[slot.task]
        starts[int(task.id)] = float(slot.start)
        units = instance.units[slot.task] or task.features
        robots = slot.members
        if len(robots) != len(units):
            disagree.append(f"activity {task.id}: {len(robots)} members for {len(units)} units")
        answered = solution.teams.get(slot.task, (solution.assignment[slot.task],))
        if tuple(answered) != robots:
            disagree.append(f"activity {task.id}: the answer's team {answered} is not {robots}")
        members[int(task.id)] = [
            (r, int(f[1:]) - 1)
            for f, r in zip(units, robots, strict=False)
            if r < project.n_resources and f.startswith("s")
        ]
    return starts, members, disagree


def solve_schedule_method(project: Project, limit_s: float) -> dict[str, Any]:
    problem = problem_of(project)
    wall, cpu = time.perf_counter(), time.process_time()
    try:
        # What `schedule` runs on a timed instance (app/solvers/schedule.py), with the
        # wall-clock net widened as in the Brandimarte benchmark: the figures are the
        # deterministic budget's, not the machine load's.
        get_solver("schedule").check_supported(problem)
        outcome = solve_schedule(problem, time_limit_s=limit_s, wall_cap_s=WALL_CAP_S)
    except DomainError as exc:
        return {"status": "refused", "error": exc.message}
    solution = Solution(
        outcome.schedule.assignment, details=outcome.details(), teams=outcome.schedule.teams
    )
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    details = solution.details
    starts, members, problems = plan_of(project, problem, solution)
    problems += plan_problems(project, starts, members)
    problems += [str(v) for v in check_schedule(problem, details["schedule"])]
    if abs(plan_makespan(project, starts) - float(details["objective_value"])) > 1e-6:
        problems.append(
            f"the answer's makespan {details['objective_value']:g} is not its plan's "
            f"{plan_makespan(project, starts):g}"
        )
    return {
        "status": details["status"],
        "makespan": float(details["objective_value"]),
        "checked_makespan": plan_makespan(project, starts),
        "bound": float(details["bound"]),
        "wall_s": wall,
        "cpu_s": cpu,
        "wall_cut": bool(details.get("budget", {}).get("wall_cut", False)),
        "wall_cap_s": float(details.get("budget", {}).get("wall_cap_s", WALL_CAP_S)),
        "model": details.get("model", ""),
        "problems": problems,
    }


def _published_plans(rows: list[dict[str, Any]]) -> list[str]:
    """How the library's own optimal plans fare in the independent check: the check of
    our answers is only as good as this."""
    checked = [r for r in rows if r.get("published_plan", "absent") != "absent"]
    if not checked:
        return []
    failed = [r["name"] for r in checked if r["published_plan"] != "ok"]
    line = (
        f"The library's own optimal plans (the last solution of each full-output file) pass "
        f"the independent check on {len(checked) - len(failed)} of {len(checked)} instances, "
        "at their published makespans"
    )
    return ["", line + (f"; **not on {', '.join(failed)}**." if failed else ".")]


RESULTS = Path(os.environ.get("MSPSP_RESULTS", tempfile.gettempdir())) / "mspsp_set2c.json"


def _published(published: dict[str, Published], name: str) -> Published:
    if name not in published:
        raise ValueError(f"{name}: no row for it in the local copy's {RESULTS_2C}")
    return published[name]


def row_best(row: dict[str, Any]) -> int:
    return int(row["published"]["makespan"])


def _published_plan_check(folder: Path, project: Project, best: int) -> str:
    """The library's own optimal plan through the independent check: "ok" when it passes
    at its published makespan, else what is wrong; "absent" without its output file."""
    text = published_output(folder, project.name)
    if text is None:
        return "absent"
    try:
        starts, members = published_plan(project, text)
    except ValueError as exc:
        return str(exc)
    problems = plan_problems(project, starts, members)
    if plan_makespan(project, starts) != best:
        problems.append(f"makespan {plan_makespan(project, starts):g}, published {best}")
    return "ok" if not problems else "; ".join(problems[:3])


def measure(
    folder: Path, pattern: str, limit: int | None, *, kept_only: bool = False
) -> list[dict[str, Any]]:
    """One row per instance, kept in RESULTS as it goes. With MSPSP_REUSE=1 the rows
    already kept there are reused and only the other instances measured (a cut run
    resumes; a finished one re-renders without measuring); a kept row measured by another
    revision of the app has `schedule` measured again (the plain model is not the app's,
    its result is kept). `kept_only` measures nothing and renders the kept rows of the
    selection (a run cut for good; stale rows marked)."""
    published = published_results(folder)
    kept: dict[str, dict[str, Any]] = {}
    if os.environ.get("MSPSP_REUSE") == "1" and RESULTS.exists():
        kept = {row["name"]: row for row in json.loads(RESULTS.read_text())}
    rows, now = [], revision()
    for path in set_2c(folder, pattern)[:limit]:
        old = kept.get(path.stem)
        if old is not None and (kept_only or old.get("revision") == now):
            rows.append(old)
            continue
        if kept_only:
            continue
        project = read_dzn(path)
        if old is not None:
            old.update(schedule=solve_schedule_method(project, LIMIT_S), revision=now)
            rows.append(old)
            RESULTS.write_text(json.dumps(list(kept.values())))
            print(f"{project.name} (schedule again): {old['schedule']}", file=sys.stderr)
            continue
        instance = project_instance(project)
        row: dict[str, Any] = {
            "name": project.name,
            "tasks": instance.n_tasks,
            "teams": sum(1 for t in instance.tasks if t.team is not None),
            "robots": project.n_resources,
            "skills": project.n_skills,
            "published": dataclasses.asdict(_published(published, project.name)),
            "load": os.getloadavg()[0],
            "revision": now,
        }
        row["published_plan"] = _published_plan_check(folder, project, row_best(row))
        row["schedule"] = solve_schedule_method(project, LIMIT_S)
        row["plain"] = plain_model(project, time_limit_s=PLAIN_LIMIT_S)
        rows.append(row)
        kept[project.name] = row
        RESULTS.write_text(json.dumps(list(kept.values())))
        print(f"{project.name}: {row}", file=sys.stderr)
    return rows


# -- the section -----------------------------------------------------------------------------


def _num(v: float | None) -> str:
    return "-" if v is None else f"{v:g}"


def verdicts(rows: list[dict[str, Any]]) -> dict[str, list[str]]:
    """The instances in each class the acceptance counts."""
    keys = ["run", "reached", "proven", "false", "below", "refused", "broken"]
    keys += ["bound_over", "plain_only"]
    out: dict[str, list[str]] = {k: [] for k in keys}
    for r in rows:
        s, best = r["schedule"], r["published"]["makespan"]
        if s["status"] == "refused":
            out["refused"].append(r["name"])
            continue
        out["run"].append(r["name"])
        if s["problems"]:
            out["broken"].append(r["name"])
        if s["makespan"] <= best + 1e-6:
            out["reached"].append(r["name"])
        if s["makespan"] < best - 1e-6:
            out["below"].append(r["name"])
        if s["status"] == "optimal":
            out["proven"].append(r["name"])
            if s["makespan"] > best + 1e-6:
                out["false"].append(r["name"])
        if s["bound"] > best + 1e-6 and r["published"]["proven"]:
            out["bound_over"].append(r["name"])
        plain = r.get("plain") or {}
        if s["status"] != "optimal" and plain.get("status") == "optimal":
            out["plain_only"].append(r["name"])
    return out


def _row(r: dict[str, Any], mark: str) -> tuple[Any, ...]:
    s, plain = r["schedule"], r.get("plain")
    ref = "-" if plain is None else f"{plain['status']} {_num(plain['makespan'])}"
    if s["status"] == "refused":
        ours: tuple[Any, ...] = ("refused", "-", "-", "-", "-")
    else:
        flag = (
            " **FALSE OPTIMAL**"
            if s["status"] == "optimal" and (s["makespan"] > r["published"]["makespan"] + 1e-6)
            else ""
        )
        flag += " **INFEASIBLE**" if s["problems"] else ""
        ours = (
            f"{s['makespan']:g}{flag}",
            f"{s['bound']:g}",
            s["status"] + (" (wall cut)" if s["wall_cut"] else ""),
            "yes" if s["status"] == "optimal" else "no",
            f"{s['cpu_s']:.1f} s / {s['wall_s']:.1f} s",
        )
    return (
        r["name"].removeprefix("inst_set2c_") + mark,
        f"{r['tasks']} ({r['teams']})",
        r["robots"],
        r["published"]["makespan"],
        *ours,
        ref,
    )


def _caps(rows: list[dict[str, Any]]) -> str:
    """The wall-clock nets the rows ran under (rows kept before the benchmark widened it
    ran under the solver's default, 10 x the limit + 10 s)."""
    default = WALL_CAP_FACTOR * LIMIT_S + WALL_CAP_EXTRA_S
    caps = sorted(
        {
            r["schedule"].get("wall_cap_s", default)
            for r in rows
            if r["schedule"]["status"] != "refused"
        }
    )
    return " and ".join(f"{c:g} s" for c in caps) or f"{WALL_CAP_S:g} s"


def body(rows: list[dict[str, Any]], folder_note: str, image: str | None = None) -> str:
    v = verdicts(rows)
    n = len(v["run"])
    lines = [
        f"Set 2c of MSPSP-InstLib ({SOURCE}; Young, Feydy & Schutt, CP 2017), read from a "
        f"local copy ({folder_note}; not committed: the library has no licence). Each "
        "instance is a timed team instance (`benchmarks/mspsp.py`): resources as robots whose "
        "`skills` are their masteries (success 1.0, so only the makespan counts), each "
        "activity a task with its duration, `after` its predecessors and `team: {skill: "
        "units}` (one unit of one skill: a one-robot task); the dummy start and end dropped. "
        f"`schedule` with objective `makespan`, no cap, `time_limit_s` {LIMIT_S:g} (a "
        "deterministic budget, one worker; wall time depends on the machine's load; the "
        f"wall-clock net was {_caps(rows)}, and a status marked *wall cut* stopped at it "
        "before its budget was spent). Every answer is "
        "checked by the app's feasibility check and by an independent check against the "
        "`.dzn` data. The last column is the plain CP-SAT MSPSP model written in the "
        f"benchmark (one worker, the same {PLAIN_LIMIT_S:g} s deterministic budget), a "
        f"reference for the reading (line below the table). Machine: {machine()}.",
        "",
        table(
            [
                "instance",
                "tasks (teams)",
                "robots",
                "published optimum",
                "makespan",
                "bound",
                "status",
                "proven",
                "CPU / wall",
                "plain model",
            ],
            [_row(r, stale_mark(rows, r)) for r in rows],
        ),
        "",
    ]
    lines += [revision_line(rows, "`schedule` (the app at commit {})"), ""]
    lines += _summary(v, n)
    lines += _published_plans(rows)
    lines += plain_line(rows)
    if image:
        lines += ["", f"![CPU per instance, schedule against the plain model]({image})"]
    return "\n".join(lines) + "\n"


def _summary(v: dict[str, list[str]], n: int) -> list[str]:
    if v["refused"] and not n:
        return [
            f"**Not measured:** `schedule` refused all {len(v['refused'])} instances (timed "
            "team tasks are not scheduled yet; docs/allocation.md#teams). The reading is "
            "checked by the plain model's column."
        ]
    reached = len(v["reached"]) == n
    proven = 3 * len(v["proven"]) >= 2 * n
    out = [
        f"**Acceptance (issue 30):** published optimum reached on {len(v['reached'])} of "
        f"{n} instances run ({'met' if reached else '**missed**'}); proven optimal on "
        f"{len(v['proven'])} of {n} (at least two thirds: {'met' if proven else '**missed**'}); "
        + (
            f"**FALSE OPTIMAL on {len(v['false'])}: {', '.join(v['false'])}**"
            if v["false"]
            else "no false optimal"
        )
        + "."
    ]
    for key, what in (
        ("broken", "plans that break the MSPSP's rules (independent check)"),
        ("below", "makespans below a published optimum (a reading or checking error)"),
        ("bound_over", "bounds above a proven published optimum (a wrong bound)"),
        ("refused", "instances refused"),
        ("plain_only", "instances the plain model proves and `schedule` does not"),
    ):
        if v[key]:
            out.append(f"- **{len(v[key])} {what}:** {', '.join(v[key])}")
    return out


def section(
    folder: str | None = None,
    pattern: str = PATTERN,
    limit: int | None = None,
    *,
    kept_only: bool = False,
) -> str:
    found = local_copy(folder)
    if found is None:
        return (
            f"{HEADING}\n\nSkipped: no local copy of MSPSP-InstLib. Clone {SOURCE} and set "
            f"{ENV} to its folder (or pass `--dir`), then run `python -m benchmarks.mspsp_bench`.\n"
        )
    rows = measure(found, pattern, limit, kept_only=kept_only)
    selected = len(set_2c(found, pattern)[:limit])
    note = f"{ENV} or `--dir`; instances `{pattern}`: {len(rows)} of {selected} measured"
    image = cpu_figure(rows) if rows else None
    return f"{HEADING}\n\n{body(rows, note, image)}"


def run() -> Section:
    """For `make bench` (benchmarks/report.py): the folder from $LTAA_MSPSP_DIR."""
    text = section()
    images = ["img/mspsp_set2c_cpu.png"] if "mspsp_set2c_cpu.png" in text else []
    return Section(TITLE, text.removeprefix(f"{HEADING}\n\n"), images)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.mspsp_bench")
    parser.add_argument("--dir", help=f"MSPSP-InstLib's folder (default ${ENV})")
    parser.add_argument("--pattern", default=PATTERN, help="set 2c instances (a glob)")
    parser.add_argument("--limit", type=int, default=None, help="at most this many")
    parser.add_argument(
        "--kept-only",
        action="store_true",
        help="measure nothing: render the rows kept by earlier runs (with MSPSP_REUSE=1)",
    )
    args = parser.parse_args(argv)
    text = section(args.dir, args.pattern, args.limit, kept_only=args.kept_only)
    write_section(HEADING, text)
    print(text)


if __name__ == "__main__":
    main(sys.argv[1:])
