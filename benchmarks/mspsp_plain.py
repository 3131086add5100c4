"""The plain CP-SAT model of the MSPSP, written here on its own (not the app's `schedule`):
the independent reference of benchmarks/mspsp_bench.py, showing that the reading of
MSPSP-InstLib matches the published optima whatever the app's solver does; and the figure
that sets `schedule`'s CPU time against it."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from ortools.sat.python import cp_model

from app.solvers.cpsat.common import DET_PER_S
from benchmarks.common import IMG
from benchmarks.mspsp import Project


def plain_model(project: Project, *, time_limit_s: float) -> dict[str, Any]:
    """The textbook MSPSP in CP-SAT, on its own: per (activity, resource, skill) a
    contribution literal, per skill the required count, a resource contributes at most
    one skill per activity, an optional interval per (activity, resource) in a no-overlap
    per resource, finish-to-start precedences, minimise the latest end. One worker."""
    m = cp_model.CpModel()
    horizon = sum(project.durations)
    acts = [a for a in range(project.n_activities) if project.durations[a] > 0]
    start = {a: m.new_int_var(0, horizon, f"s{a}") for a in range(project.n_activities)}
    busy: list[list[cp_model.IntervalVar]] = [[] for _ in range(project.n_resources)]
    for a in acts:
        need = project.requirements[a]
        contrib: dict[tuple[int, int], cp_model.IntVar] = {}
        for r, row in enumerate(project.mastery):
            for s, has in enumerate(row):
                if has and need[s] > 0:
                    contrib[r, s] = m.new_bool_var(f"c{a}_{r}_{s}")
        for s, units in enumerate(need):
            if units:
                m.add(sum(v for (_, k), v in contrib.items() if k == s) == units)
        for r in range(project.n_resources):
            mine = [v for (q, _), v in contrib.items() if q == r]
            if not mine:
                continue
            present = m.new_bool_var(f"x{a}_{r}")
            m.add(sum(mine) == present)
            busy[r].append(
                m.new_optional_fixed_size_interval_var(
                    start[a], project.durations[a], present, f"i{a}_{r}"
                )
            )
    for intervals in busy:
        m.add_no_overlap(intervals)
    # The MiniZinc model's redundant cumulatives: per skill (its masters at once) and in
    # all (the resources at once); without them the bound stalls on a third of set 2c.
    spans = {
        a: m.new_fixed_size_interval_var(start[a], project.durations[a], f"a{a}") for a in acts
    }
    for s in range(project.n_skills):
        masters = sum(row[s] for row in project.mastery)
        used = [a for a in acts if project.requirements[a][s]]
        m.add_cumulative(
            [spans[a] for a in used], [project.requirements[a][s] for a in used], masters
        )
    m.add_cumulative(
        [spans[a] for a in acts], [sum(project.requirements[a]) for a in acts], project.n_resources
    )
    for before, after in project.precedences:
        m.add(start[after - 1] >= start[before - 1] + project.durations[before - 1])
    makespan = m.new_int_var(0, horizon, "makespan")
    for a in range(project.n_activities):
        m.add(makespan >= start[a] + project.durations[a])
    m.minimize(makespan)
    solver = cp_model.CpSolver()
    # the same deterministic budget as `schedule` is given for `time_limit_s`
    solver.parameters.max_deterministic_time = time_limit_s * DET_PER_S
    solver.parameters.num_workers = 1
    began = time.process_time()
    status = solver.status_name(solver.solve(m))
    found = status in ("OPTIMAL", "FEASIBLE")
    return {
        "status": status.lower(),
        "makespan": int(solver.objective_value) if found else None,
        "bound": solver.best_objective_bound,
        "cpu_s": time.process_time() - began,
    }


def plain_line(rows: list[dict[str, Any]]) -> list[str]:
    """The sentence under the table: how the plain model fares against the published optima."""
    plain = [(r["plain"], r["published"]["makespan"]) for r in rows if r.get("plain")]
    if not plain:
        return []
    found = [(p, best) for p, best in plain if p["makespan"] is not None]
    reached = sum(1 for p, best in found if p["makespan"] <= best)
    below = sum(1 for p, best in found if p["makespan"] < best)
    proven = sum(1 for p, _ in plain if p["status"] == "optimal")
    ours = sum(r["schedule"].get("cpu_s", 0.0) for r in rows if r.get("plain"))
    theirs = sum(p.get("cpu_s", 0.0) for p, _ in plain)
    return [
        "",
        f"The plain model reaches the published optimum on {reached} of {len(plain)}, proves "
        f"{proven}, and is below a published optimum on {below} (a wrong reading would show "
        f"there). CPU over these {len(plain)} instances: `schedule` {ours:.0f} s (the call: "
        f"models, checks and search), the plain model {theirs:.0f} s (its search).",
    ]


def cpu_figure(rows: list[dict[str, Any]], directory: Path = IMG) -> str:
    """CPU seconds per instance: `schedule` against the plain model (log-log), each point
    marked by what `schedule` answered."""
    import matplotlib

    matplotlib.use("Agg")  # headless
    import matplotlib.pyplot as plt

    from benchmarks.plots import PALETTE, save

    fig, ax = plt.subplots(figsize=(5.2, 4.4))
    kinds = {
        "proven optimal": (PALETTE[2], "o"),
        "published optimum, not proven": (PALETTE[1], "s"),
        "above the published optimum": (PALETTE[3], "X"),
    }
    for label, (colour, marker) in kinds.items():
        xs, ys = [], []
        for r in rows:
            s, plain = r["schedule"], r.get("plain")
            if s["status"] == "refused" or plain is None:
                continue
            reached = s["makespan"] <= r["published"]["makespan"] + 1e-6
            kind = (
                "proven optimal"
                if s["status"] == "optimal"
                else "published optimum, not proven"
                if reached
                else "above the published optimum"
            )
            if kind == label:
                xs.append(max(plain["cpu_s"], 0.01))
                ys.append(max(s["cpu_s"], 0.01))
        ax.scatter(xs, ys, c=colour, marker=marker, label=f"{label} ({len(xs)})", alpha=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    lo, hi = 0.01, 100.0
    ax.plot([lo, hi], [lo, hi], color="black", linewidth=0.8, linestyle="--")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_xlabel("plain CP-SAT model, CPU s")
    ax.set_ylabel("schedule, CPU s")
    ax.set_title("MSPSP set 2c: CPU per instance (30 s budget each)")
    ax.legend(fontsize=8, loc="upper left")
    return save(fig, "mspsp_set2c_cpu.png", directory)
