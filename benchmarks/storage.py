"""Long-lived deployments (issue 16): a run's checkpoint storage stays bounded while it runs.

The checkpoint file and its -wal are sampled every 50 ms during one rules run in a fresh
data directory; the peak of their sum is the disk the run needed at any moment.
"""

from __future__ import annotations

from benchmarks.common import Section, fmt_time, synthetic_instance, table
from benchmarks.durable import StorageMeasure, measure_storage

SIZES = (1_000, 10_000)
N_ROBOTS = 4
TARGET_PEAK_10K = 20 * 1024 * 1024
# Measured before pruning (issue 16's report, `make run`, 10,000 tasks): a 164 MB file and
# a 169 MB -wal left after the run; the 1,000-task durable time from the previous report.
BEFORE_PEAK_10K = 333_000_000
BEFORE_SECONDS = {1_000: "8.58 s (durable-run median, previous report)", 10_000: "111 s"}


def _mb(n: int) -> str:
    return f"{n / 1_000_000:.2f} MB"


def storage_part(measures: list[StorageMeasure]) -> str:
    rows = [
        [
            f"{m.n_tasks:,}",
            fmt_time(m.seconds),
            BEFORE_SECONDS.get(m.n_tasks, "-"),
            f"{m.samples:,}",
            _mb(m.peak_bytes),
            _mb(m.peak_file_bytes),
            _mb(m.peak_wal_bytes),
            _mb(m.final_bytes),
        ]
        for m in measures
    ]
    large = next(m for m in measures if m.n_tasks == 10_000)
    verdict = "met" if large.peak_bytes <= TARGET_PEAK_10K else "**missed**"
    return (
        "One `rules` run per size through the real `RunWorker` (synthetic instance, seed 0, "
        f"{N_ROBOTS} robots, `balanced`), the checkpoint file and its -wal sampled every "
        "50 ms while it ran. The compact saver keeps a thread's latest 4 checkpoints, "
        "pruning the older ones (and their writes) every 20 checkpoints; the WAL has a "
        "4 MiB `journal_size_limit` and is truncated every 10 prunes. The wall time is one "
        "run (no median) beside the figure measured before pruning.\n\n"
        + table(
            [
                "tasks",
                "wall time",
                "before",
                "samples",
                "peak file + -wal",
                "peak file",
                "peak -wal",
                "after completion",
            ],
            rows,
        )
        + f"\n\nTarget: peak checkpoint storage of the 10,000-task run ≤ 20 MB (before: "
        f"{BEFORE_PEAK_10K / 1_000_000:.0f} MB left after the run): "
        f"{_mb(large.peak_bytes)} — {verdict}.\n"
    )


def run() -> Section:
    measures = [measure_storage(synthetic_instance(n, N_ROBOTS, seed=0)) for n in SIZES]
    return Section("Long-lived deployments: bounded checkpoint storage", storage_part(measures))
