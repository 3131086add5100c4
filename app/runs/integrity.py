"""The check made before a run resumes: is the stored record consistent with the checkpoint?"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from app.domain.metrics import balance_score
from app.domain.phases import detect_phase
from app.graph.recorder import DecisionRecord


@dataclass(frozen=True)
class IntegrityReport:
    ok: bool
    decisions_stored: int
    contiguous: bool
    checkpoint_task_index: int | None
    resume_at_task: int
    loads_from_decisions: list[int]
    loads_in_checkpoint: list[int] | None
    loads_consistent: bool
    phase: str
    balance_score: float
    problems: list[str]

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def check_integrity(
    *,
    decisions: list[DecisionRecord],
    n_tasks: int,
    n_robots: int,
    checkpoint: dict[str, Any] | None,
) -> IntegrityReport:
    """Queue position, loads recomputed from stored decisions, phase re-derived.

    A checkpoint may lag the decisions table by the one task whose `store_and_route`
    node wrote its decision but did not finish: that node re-runs and upserts the same
    row, so a lag of exactly one is consistent. Anything else is reported as a problem.
    """
    problems: list[str] = []
    indices = [d.task_index for d in decisions]
    contiguous = indices == list(range(len(indices)))
    if not contiguous:
        problems.append(f"decision task indices are not 0..{len(indices) - 1}: {indices[:10]}")
    loads = [0] * n_robots
    for d in decisions:
        loads[d.robot] += 1
        if d.loads_after != loads:
            problems.append(
                f"task {d.task_index}: stored loads_after {d.loads_after} but the "
                f"decisions so far give {loads}"
            )
            break

    cp_index = checkpoint.get("task_index") if checkpoint else None
    cp_loads = list(checkpoint["loads"]) if checkpoint and "loads" in checkpoint else None
    loads_consistent = True
    if cp_index is not None:
        lag = len(decisions) - cp_index
        if lag not in (0, 1):
            problems.append(
                f"checkpoint is at task {cp_index} but {len(decisions)} decisions are stored"
            )
        if cp_loads is not None:
            expected = [0] * n_robots
            for d in decisions[: min(cp_index, len(decisions))]:
                expected[d.robot] += 1
            # The checkpoint may already count the current task (after update_workload),
            # whose decision is stored only by the next node: its robot is then the
            # checkpoint's own `robot`.
            current = decisions[cp_index] if cp_index < len(decisions) else None
            robot = current.robot if current is not None else (checkpoint or {}).get("robot")
            counted = expected.copy()
            if isinstance(robot, int) and 0 <= robot < n_robots:
                counted[robot] += 1
            loads_consistent = cp_loads in (expected, counted)
            if not loads_consistent:
                problems.append(
                    f"checkpoint loads {cp_loads} disagree with the stored decisions ({expected})"
                )
    resume_at = len(decisions)
    target = n_tasks / n_robots
    return IntegrityReport(
        ok=not problems,
        decisions_stored=len(decisions),
        contiguous=contiguous,
        checkpoint_task_index=cp_index,
        resume_at_task=resume_at,
        loads_from_decisions=loads,
        loads_in_checkpoint=cp_loads,
        loads_consistent=loads_consistent,
        phase=detect_phase(resume_at, n_tasks).value,
        balance_score=balance_score(loads, target),
        problems=problems,
    )
