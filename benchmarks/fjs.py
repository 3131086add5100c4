"""Flexible job shop instances (the `.fjs` format of Brandimarte's Mk01-Mk15) and the plain
CP-SAT model the benchmark compares the `schedule` solver with.

The format: a first line `<jobs> <machines> [<mean machines per operation>]`, then one line
per job: its number of operations, and per operation the number of machines that can run
it followed by that many `<machine> <minutes>` pairs, machines numbered from 1.

As an LTAA instance: each operation is a task (`after` the job's previous operation),
each machine a robot, and a task's duration map names the machines that can run it (the
others cannot take it). No zones, so no travel; every robot has the same success rate,
so every allocation has the same expected success and the makespan alone decides.

`plain_model_makespan` is the textbook model, written here on its own as the independent
reference: one optional interval per (operation, machine), `AddNoOverlap` per machine,
a chain per job, minimise the makespan.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from ortools.sat.python import cp_model

from app.domain.models import Instance, Robot, Task

DATA = Path(__file__).parent / "data" / "brandimarte"
# Best-known makespans from the literature (optimal where proven: Mk01, Mk03, Mk04, Mk08,
# Mk09; the others are the best upper bounds, as collected in SchedulingLab/fjsp-instances'
# instances.json with the lower bounds known there).
BEST_KNOWN = {
    "mk01": 40,
    "mk02": 26,
    "mk03": 204,
    "mk04": 60,
    "mk05": 172,
    "mk06": 58,
    "mk07": 139,
    "mk08": 523,
    "mk09": 307,
    "mk10": 197,
}
FEATURE = "machining"


@dataclass(frozen=True)
class Shop:
    name: str
    n_machines: int
    # per job, per operation: {machine index (0-based): minutes}
    jobs: tuple[tuple[dict[int, int], ...], ...]

    @property
    def n_operations(self) -> int:
        return sum(len(job) for job in self.jobs)


def read_fjs(path: Path) -> Shop:
    """A `.fjs` file; ValueError naming the line when it does not follow the format."""
    lines = [line.split() for line in path.read_text().splitlines() if line.strip()]
    if not lines or len(lines[0]) < 2:
        raise ValueError(f"{path}: the first line must be '<jobs> <machines> [<mean>]'")
    n_jobs, n_machines = int(lines[0][0]), int(lines[0][1])
    jobs = []
    for number, fields in enumerate(lines[1 : n_jobs + 1], start=2):
        values = [int(v) for v in fields]
        k, ops = 1, []
        for _ in range(values[0]):
            count = values[k]
            pairs = values[k + 1 : k + 1 + 2 * count]
            if len(pairs) != 2 * count:
                raise ValueError(f"{path}:{number}: an operation lists fewer machines than it says")
            ops.append({pairs[i] - 1: pairs[i + 1] for i in range(0, len(pairs), 2)})
            k += 1 + 2 * count
        jobs.append(tuple(ops))
    if len(jobs) != n_jobs:
        raise ValueError(f"{path}: {n_jobs} jobs announced, {len(jobs)} found")
    return Shop(path.stem, n_machines, tuple(jobs))


def shop_instance(shop: Shop) -> Instance:
    robots = tuple(Robot(name=f"m{m + 1}", success={FEATURE: 0.9}) for m in range(shop.n_machines))
    tasks = []
    for j, job in enumerate(shop.jobs):
        for o, durations in enumerate(job):
            tasks.append(
                Task(
                    id=f"j{j + 1}-o{o + 1}",
                    name=f"job {j + 1} operation {o + 1}",
                    features=(FEATURE,),
                    duration={f"m{m + 1}": float(d) for m, d in durations.items()},
                    after=() if o == 0 else (f"j{j + 1}-o{o}",),
                )
            )
    return Instance(tasks=tuple(tasks), robots=robots)


@dataclass(frozen=True)
class PlainResult:
    status: str
    makespan: int | None
    bound: float
    wall_s: float


def plain_model_makespan(shop: Shop, *, time_limit_s: float, workers: int = 2) -> PlainResult:
    """The textbook flexible job shop model, solved by CP-SAT with `workers` workers."""
    m = cp_model.CpModel()
    horizon = sum(max(op.values()) for job in shop.jobs for op in job)
    per_machine: list[list[cp_model.IntervalVar]] = [[] for _ in range(shop.n_machines)]
    ends: list[cp_model.IntVar] = []
    for j, job in enumerate(shop.jobs):
        previous_end: cp_model.IntVar | None = None
        for o, op in enumerate(job):
            start = m.new_int_var(0, horizon, f"s{j}_{o}")
            end = m.new_int_var(0, horizon, f"e{j}_{o}")
            lits = []
            for machine, d in op.items():
                lit = m.new_bool_var(f"x{j}_{o}_{machine}")
                lits.append(lit)
                per_machine[machine].append(
                    m.new_optional_interval_var(start, d, end, lit, f"i{j}_{o}_{machine}")
                )
            m.add_exactly_one(lits)
            if previous_end is not None:
                m.add(start >= previous_end)
            previous_end = end
        if previous_end is not None:
            ends.append(previous_end)
    for intervals in per_machine:
        m.add_no_overlap(intervals)
    makespan = m.new_int_var(0, horizon, "makespan")
    m.add_max_equality(makespan, ends)
    m.minimize(makespan)
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = time_limit_s
    solver.parameters.num_workers = workers
    began = time.perf_counter()
    status = solver.status_name(solver.solve(m))
    wall = time.perf_counter() - began
    found = status in ("OPTIMAL", "FEASIBLE")
    return PlainResult(
        status, int(solver.objective_value) if found else None, solver.best_objective_bound, wall
    )


def brandimarte(folder: Path = DATA) -> list[Shop]:
    """Mk01-Mk10 from `folder` (the copies committed here by default)."""
    return [read_fjs(folder / f"{name}.fjs") for name in BEST_KNOWN]
