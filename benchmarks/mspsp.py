"""Multi-skill project scheduling instances (MSPSP-InstLib's MiniZinc `.dzn` files) as
LTAA team instances, their published optima, and an independent check of a plan.

MSPSP-InstLib (Young, Feydy & Schutt, CP 2017; github.com/youngkd/MSPSP-InstLib) has no
licence, so nothing of it is committed here: the benchmark reads a local copy whose folder
is given by `--dir` or the LTAA_MSPSP_DIR environment variable (docs/benchmarks.md says
where to get it).

The `.dzn` arrays this reader uses, as the library's model `models/mspsp.mzn` reads them:

- `nActs`, `dur[ACT]`: activities and their durations; activity 1 and activity `nActs` are
  the dummy start and end (duration 0, no requirement), and the model's makespan is the
  end dummy's start.
- `nSkills`, `sreq[ACT, SKILL]`: how many resources must contribute each skill to the
  activity; a resource contributes at most one skill to an activity, so the activity needs
  `sum(sreq[a])` distinct resources at once, for all of its duration.
- `nResources`, `mastery[RESOURCE, SKILL]`: the skills each resource may contribute; a
  resource works on one activity at a time.
- `nPrecs`, `pred[PREC]`, `succ[PREC]`: finish-to-start precedences (1-based activities).
- The rest (`mint`, `unpred`/`unsucc`, `USEFUL_RES`, `POTENTIAL_ACT`) is derived from
  these for the model's search and is not read.

As an LTAA instance (docs/allocation.md#teams, docs/schedules.md#the-model): each resource
is a robot `r<k>` whose `skills` are its masteries, with success 1.0 on them (0.0 on the
others), so every plan has the same expected success and the makespan alone decides.
Each activity is a task with its duration and `after` its predecessors; an activity
needing one unit of one skill is a plain one-robot task with that feature (the same
eligibility and load as a team of one: a robot with the skill), any other a task with
`team: {skill: units}`.

Two kinds of activity have no LTAA task of their own, both exactly:
- an activity of duration 0 (the two dummies, and any other) holds nothing in time, so it
  is dropped and each of its predecessors comes before each of its successors;
- an activity of positive duration needing no skill is a pure delay: it gets a robot of
  its own (`wait<a>`, whose one skill only that task needs), which delays its successors
  by its duration and takes no time from any resource. Set 2c has none.
"""

from __future__ import annotations

import csv
import io
import itertools
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from app.domain.models import Instance, Robot, Task

ENV = "LTAA_MSPSP_DIR"
SET_2C = Path("instances") / "set-2" / "set-2c"
RESULTS_2C = Path("results") / "set-2" / "set-2c" / "results"
OUTPUT_2C = Path("results") / "set-2" / "set-2c" / "full-output"
_NAME = re.compile(r"^inst_(?P<group>.+)_(?P<number>\d+)$")


@dataclass(frozen=True)
class Project:
    """One `.dzn` instance, as the file says it (activities 1-based, dummies included)."""

    name: str
    durations: tuple[int, ...]
    requirements: tuple[tuple[int, ...], ...]  # per activity, units per skill
    mastery: tuple[tuple[bool, ...], ...]  # per resource, per skill
    precedences: tuple[tuple[int, int], ...]  # (predecessor, successor)

    @property
    def n_activities(self) -> int:
        return len(self.durations)

    @property
    def n_skills(self) -> int:
        return len(self.mastery[0]) if self.mastery else 0

    @property
    def n_resources(self) -> int:
        return len(self.mastery)


# -- the .dzn text -------------------------------------------------------------------------


def parse_dzn(text: str) -> dict[str, object]:
    """`name = value;` statements with `%` comments: integers, booleans, 1-d arrays `[...]`
    and 2-d arrays `[| a, b, | c, d, |]` of either. Other values (arrays of sets) are
    kept as their text. ValueError naming the statement when one cannot be read."""
    text = re.sub(r"%[^\n]*", "", text)
    values: dict[str, object] = {}
    for statement in text.split(";"):
        if not statement.strip():
            continue
        name, eq, value = statement.partition("=")
        if not eq or not name.strip().isidentifier():
            raise ValueError(f"cannot read the statement {statement.strip()[:60]!r}")
        values[name.strip()] = _value(name.strip(), value.strip())
    return values


def _value(name: str, value: str) -> object:
    if value.startswith("[|"):
        if not value.endswith("|]"):
            raise ValueError(f"{name}: a 2-d array must end with '|]'")
        rows = [row for row in value[2:-2].split("|") if row.strip()]
        return [_scalars(name, row) for row in rows]
    if value.startswith("["):
        if not value.endswith("]"):
            raise ValueError(f"{name}: an array must end with ']'")
        if "{" in value:
            return value  # an array of sets: derived data this reader does not use
        return _scalars(name, value[1:-1])
    return _scalar(name, value)


def _scalars(name: str, items: str) -> list[int | bool]:
    return [_scalar(name, item.strip()) for item in items.split(",") if item.strip()]


def _scalar(name: str, item: str) -> int | bool:
    if item in ("true", "false"):
        return item == "true"
    try:
        return int(item)
    except ValueError:
        raise ValueError(f"{name}: {item!r} is not an integer or a boolean") from None


def _ints(values: Mapping[str, object], name: str) -> list[int]:
    value = values.get(name)
    if not isinstance(value, list) or any(
        isinstance(v, bool) or not isinstance(v, int) for v in value
    ):
        raise ValueError(f"'{name}' must be an array of integers")
    return list(value)


def _matrix(values: Mapping[str, object], name: str, rows: int, cols: int) -> list[list[object]]:
    value = values.get(name)
    if (
        not isinstance(value, list)
        or len(value) != rows
        or any(not isinstance(row, list) or len(row) != cols for row in value)
    ):
        raise ValueError(f"'{name}' must be a {rows} x {cols} array")
    return value


def _count(values: Mapping[str, object], name: str) -> int:
    value = values.get(name)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"'{name}' must be a whole number")
    return value


def parse_project(name: str, text: str) -> Project:
    """A `.dzn` text as a Project; ValueError naming the array that does not fit."""
    values = parse_dzn(text)
    n_acts, n_skills = _count(values, "nActs"), _count(values, "nSkills")
    n_resources, n_precs = _count(values, "nResources"), _count(values, "nPrecs")
    durations = _ints(values, "dur")
    if len(durations) != n_acts or any(d < 0 for d in durations):
        raise ValueError(f"'dur' must list {n_acts} durations of 0 or more")
    sreq = _matrix(values, "sreq", n_acts, n_skills)
    if any(isinstance(v, bool) or not isinstance(v, int) or v < 0 for row in sreq for v in row):
        raise ValueError("'sreq' must hold whole numbers of 0 or more")
    mastery = _matrix(values, "mastery", n_resources, n_skills)
    if any(not isinstance(v, bool) for row in mastery for v in row):
        raise ValueError("'mastery' must hold true or false")
    pred, succ = _ints(values, "pred"), _ints(values, "succ")
    if len(pred) != n_precs or len(succ) != n_precs:
        raise ValueError(f"'pred' and 'succ' must each list {n_precs} activities")
    if any(not 1 <= a <= n_acts for a in pred + succ):
        raise ValueError(f"'pred' and 'succ' must name activities 1 to {n_acts}")
    _check_acyclic(n_acts, list(zip(pred, succ, strict=True)))
    return Project(
        name=name,
        durations=tuple(durations),
        requirements=tuple(tuple(v for v in row if isinstance(v, int)) for row in sreq),
        mastery=tuple(tuple(v is True for v in row) for row in mastery),
        precedences=tuple(zip(pred, succ, strict=True)),
    )


def _check_acyclic(n_acts: int, edges: list[tuple[int, int]]) -> None:
    """Kahn's algorithm: ValueError naming the activities left on a cycle."""
    indegree = [0] * (n_acts + 1)
    after: dict[int, list[int]] = {}
    for before, later in edges:
        indegree[later] += 1
        after.setdefault(before, []).append(later)
    ready = [a for a in range(1, n_acts + 1) if indegree[a] == 0]
    while ready:
        for later in after.get(ready.pop(), []):
            indegree[later] -= 1
            if indegree[later] == 0:
                ready.append(later)
    stuck = [a for a in range(1, n_acts + 1) if indegree[a] > 0]
    if stuck:
        raise ValueError(f"the precedences form a cycle through activities {stuck}")


def read_dzn(path: Path) -> Project:
    try:
        return parse_project(path.stem, path.read_text(encoding="utf-8"))
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


# -- as an LTAA instance --------------------------------------------------------------------


def skill_name(s: int) -> str:
    return f"s{s + 1}"


def _predecessors(project: Project, kept: set[int]) -> dict[int, set[int]]:
    """Per kept activity, its kept predecessors, bridging every dropped activity."""
    direct: dict[int, set[int]] = {a: set() for a in range(1, project.n_activities + 1)}
    for before, after in project.precedences:
        direct[after].add(before)
    memo: dict[int, set[int]] = {}

    def kept_before(a: int) -> set[int]:  # acyclic: parse_project checked
        if a not in memo:
            out: set[int] = set()
            for b in direct[a]:
                out |= {b} if b in kept else kept_before(b)
            memo[a] = out
        return memo[a]

    return {a: kept_before(a) for a in sorted(kept)}


def project_instance(project: Project) -> Instance:
    """The project as a timed team instance (the module's docstring says how)."""
    kept = {a for a in range(1, project.n_activities + 1) if project.durations[a - 1] > 0}
    if not kept:
        raise ValueError(f"{project.name}: no activity has a positive duration")
    skills = [skill_name(s) for s in range(project.n_skills)]
    waits = [a for a in sorted(kept) if not any(project.requirements[a - 1])]
    features = skills + [f"wait{a}" for a in waits]
    own = [[skills[s] for s, has in enumerate(row) if has] for row in project.mastery]
    own += [[f"wait{a}"] for a in waits]
    names = [f"r{k + 1}" for k in range(project.n_resources)] + [f"wait{a}" for a in waits]
    robots = [
        # success 1.0 on its skills (0.0 elsewhere: every robot rates every feature)
        Robot(name=name, success={f: float(f in mine) for f in features}, skills=tuple(mine))
        for name, mine in zip(names, own, strict=True)
    ]
    before = _predecessors(project, kept)
    tasks = []
    for a in sorted(kept):
        need = {skills[s]: n for s, n in enumerate(project.requirements[a - 1]) if n > 0}
        if not need:
            need = {f"wait{a}": 1}
        single = len(need) == 1 and next(iter(need.values())) == 1
        tasks.append(
            Task(
                id=a,
                name=f"activity {a}",
                features=tuple(need),
                duration=float(project.durations[a - 1]),
                after=tuple(sorted(before[a])),
                team=None if single else need,
            )
        )
    return Instance(tasks=tuple(tasks), robots=tuple(robots))


# -- the published optima and the local copy ----------------------------------------------


@dataclass(frozen=True)
class Published:
    makespan: int
    proven: bool  # the `optimal` column: 1 when the search completed


def published_results(folder: Path) -> dict[str, Published]:
    """Set 2c's results, by instance name, from `results/set-2/set-2c/results/`.

    One CSV file per instance group (`results_<group>_pris.txt`, header `instNum,optimal,
    LB,makespan,...`), one row per instance of the group in order: row k is instance
    `inst_<group>_0k` (the `instNum` column reads 0 on every row, so the row's place is the
    number; the library's per-instance full outputs agree, row for row)."""
    out: dict[str, Published] = {}
    for path in sorted((folder / RESULTS_2C).glob("results_*_pris.txt")):
        group = path.name[len("results_") : -len("_pris.txt")]
        rows = list(csv.DictReader(io.StringIO(path.read_text(encoding="utf-8"))))
        for k, row in enumerate(rows):
            try:
                out[f"inst_{group}_{k:02d}"] = Published(
                    int(row["makespan"]), row["optimal"].strip() == "1"
                )
            except (KeyError, TypeError, ValueError):
                raise ValueError(
                    f"{path}: row {k + 2} lacks a whole 'makespan' and an 'optimal' flag"
                ) from None
    return out


def published_plan(
    project: Project, text: str
) -> tuple[dict[int, float], dict[int, list[tuple[int, int]]]]:
    """The last solution of a full-output file (MiniZinc's output, solutions separated by
    `----------`): `start times = [...]` per activity and `contribution = [...]`, the
    booleans of contrib[ACT, RESOURCE, SKILL] flattened row-major, as starts and
    (resource, skill) members for `plan_problems`. ValueError when it holds none."""
    solutions = [part for part in text.split("----------") if "start times" in part]
    if not solutions:
        raise ValueError("no solution with start times in the output")
    last = solutions[-1]
    found = re.search(r"start times = \[([^\]]*)\]", last)
    flags = re.search(r"contribution = \[([^\]]*)\]", last)
    if found is None or flags is None:
        raise ValueError("the last solution lacks start times or contributions")
    times = [int(v) for v in found.group(1).split(",")]
    given = [v.strip() == "true" for v in flags.group(1).split(",")]
    n_r, n_s = project.n_resources, project.n_skills
    if len(times) != project.n_activities or len(given) != project.n_activities * n_r * n_s:
        raise ValueError("the solution's arrays do not fit the instance")
    starts = {
        a: float(times[a - 1])
        for a in range(1, project.n_activities + 1)
        if project.durations[a - 1] > 0
    }
    members = {
        a: [(r, s) for r in range(n_r) for s in range(n_s) if given[((a - 1) * n_r + r) * n_s + s]]
        for a in starts
    }
    return starts, members


def published_output(folder: Path, name: str) -> str | None:
    """The full-output text of instance `name` (`inst_<group>_<k>`), if the copy has it."""
    match = _NAME.match(name)
    if match is None:
        return None
    path = folder / OUTPUT_2C / f"full-output_{match['group']}_pris_{match['number']}.txt"
    return path.read_text(encoding="utf-8") if path.is_file() else None


def local_copy(given: str | None = None) -> Path | None:
    """The local MSPSP-InstLib folder: `given`, else $LTAA_MSPSP_DIR; None when neither
    names a folder holding set 2c."""
    where = given or os.environ.get(ENV)
    if not where:
        return None
    folder = Path(where).expanduser()
    return folder if (folder / SET_2C).is_dir() else None


def set_2c(folder: Path, pattern: str = "*") -> list[Path]:
    """Set 2c's `.dzn` files whose stem matches `pattern` (a glob), in name order."""
    return sorted((folder / SET_2C).glob(f"{pattern}.dzn"))


def group_of(name: str) -> str:
    match = _NAME.match(name)
    return match.group("group") if match else name


# -- an independent check of a plan ---------------------------------------------------------


def plan_problems(
    project: Project,
    starts: Mapping[int, float],
    members: Mapping[int, Sequence[tuple[int, int]]],
) -> list[str]:
    """What breaks the MSPSP's rules in a plan, read against the `.dzn` data alone (not
    the LTAA instance): `starts[a]` per activity of positive duration, `members[a]` its
    (resource, skill) pairs, 0-based. Empty when the plan is feasible."""
    out: list[str] = []
    spans: dict[int, list[tuple[float, float, int]]] = {}
    for a in range(1, project.n_activities + 1):
        if project.durations[a - 1] == 0:
            continue
        if a not in starts:
            out.append(f"activity {a} has no start")
            continue
        start, end = starts[a], starts[a] + project.durations[a - 1]
        if start < 0:
            out.append(f"activity {a} starts before 0")
        pairs = list(members.get(a, ()))
        if len({r for r, _ in pairs}) != len(pairs):
            out.append(f"activity {a}: a resource contributes twice")
        got = [0] * project.n_skills
        for r, s in pairs:
            got[s] += 1
            if not project.mastery[r][s]:
                out.append(f"activity {a}: resource {r + 1} has not mastered skill {s + 1}")
            spans.setdefault(r, []).append((start, end, a))
        want = list(project.requirements[a - 1])
        if any(want) and got != want:
            out.append(f"activity {a}: skills covered {got}, required {want}")
    ends = {a: starts[a] + project.durations[a - 1] for a in starts}
    for before, after in project.precedences:
        # a zero-duration activity starts as early as its predecessors allow
        start_after = starts.get(after, _earliest(project, starts, after))
        end_before = ends.get(before, _earliest(project, starts, before))
        if start_after < end_before - 1e-6:
            out.append(f"activity {after} starts at {start_after:g}, before {before} ends")
    for r, busy in spans.items():
        busy.sort()
        for (_, end, a), (start, _, b) in itertools.pairwise(busy):
            if start < end - 1e-6:
                out.append(f"resource {r + 1} works on activities {a} and {b} at once")
    return out


def _earliest(project: Project, starts: Mapping[int, float], a: int) -> float:
    """A zero-duration activity's time: the latest end among its predecessors."""
    ends = [
        starts.get(b, _earliest(project, starts, b)) + project.durations[b - 1]
        for b, c in project.precedences
        if c == a
    ]
    return max(ends, default=0.0)


def plan_makespan(project: Project, starts: Mapping[int, float]) -> float:
    return max(starts[a] + project.durations[a - 1] for a in starts)
