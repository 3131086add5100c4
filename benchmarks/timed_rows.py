"""Re-measure the "Plans in time" section's CP-SAT rows, LTAA rows and `/allocate` lines
alone (`python -m benchmarks.timed_schedules --cpsat`), keeping the other methods' rows.

When the scheduler changes, only those rows move: the other methods' plans do not depend
on it (their regret columns do, and `timed_schedules.body` recomputes them).
"""

from __future__ import annotations

import os
import sys
import time

from benchmarks.timed_schedules import (
    API_LIMITS,
    TITLE,
    CpSatRow,
    MethodRow,
    _figure,
    api_seconds,
    body,
    instances,
    ltaa_rows,
    run_cpsat,
)


def rows_only() -> None:
    """Re-measure CP-SAT's rows, the LTAA rows and the `/allocate` lines (the scheduler
    changed) and keep the other methods' rows as the section has them: their plans do not
    depend on the scheduler, only their regret columns, which `body` recomputes."""
    import datetime

    from benchmarks.common import DOCS, write_section

    report = (DOCS / "benchmarks.md").read_text(encoding="utf-8")
    start = report.index(f"## {TITLE}")
    end = report.find("\n## ", start + len(TITLE))
    kept = _method_rows(report[start : None if end < 0 else end])
    began, load = time.perf_counter(), os.getloadavg()[0]
    cp_rows: list[CpSatRow] = []
    method_rows: list[tuple[CpSatRow, MethodRow]] = []
    problems = instances()
    for label, problem, limit in problems:
        row, _ = run_cpsat(label, problem, limit)
        cp_rows.append(row)
        print(f"{label}: {row.status} {row.makespan} bound {row.bound}", file=sys.stderr)
        others = [m for m in kept if m.label == label and not m.method.startswith("ltaa")]
        method_rows += [(row, m) for m in others + ltaa_rows(label, problem)]
    api = {limit: api_seconds(problems[0][1], limit) for limit in API_LIMITS}
    text = body(cp_rows, method_rows, api, _figure(cp_rows, method_rows))
    note = (
        f"_CP-SAT's rows, the LTAA rows and the `/allocate` lines re-measured on "
        f"{datetime.date.today()} with `python -m benchmarks.timed_schedules --cpsat` (load "
        f"{load:.1f}-{os.getloadavg()[0]:.1f}); the other methods' rows (ES, makespan, "
        "violations, wall) as measured before, their regrets recomputed against these rows._"
    )
    took = time.perf_counter() - began
    write_section(
        f"## {TITLE}", f"## {TITLE}\n\n{text}\n{note}\n\n_Section measured in {took:.1f} s._\n"
    )


def _method_rows(section: str) -> list[MethodRow]:
    """The methods table of the section as written (`body`'s columns)."""
    lines = section.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("| instance | method |"))
    rows = []
    for line in lines[at + 2 :]:
        if not line.startswith("| "):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        label, method, es, regret, makespan, _, _, violations, wall, note = cells
        rows.append(
            MethodRow(
                label,
                method,
                None if es == "-" else float(es),
                None if makespan == "-" else float(makespan.replace(",", "")),
                int(violations),
                float(wall.removesuffix(" s")),
                note,
                None if regret == "-" else float(regret),
            )
        )
    return rows
