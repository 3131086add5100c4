"""The MSPSP-InstLib reader of the set-2c benchmark (benchmarks/mspsp.py): a small `.dzn`
text written here (not a copy of the library's files), read as a timed team instance
(docs/allocation.md#teams), the published results' layout, the independent plan check,
and the plain CP-SAT model against a brute force over activity orders and teams."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import pytest

from app.domain.errors import DomainError
from benchmarks.mspsp import (
    RESULTS_2C,
    SET_2C,
    Project,
    local_copy,
    parse_dzn,
    parse_project,
    plan_problems,
    project_instance,
    published_results,
    set_2c,
)
from benchmarks.mspsp_bench import (
    body,
    plain_model,
    problem_of,
    section,
    solve_schedule_method,
)

# Activities 1 and 7 are the dummies. 2 needs one s1; 3 one s1 and one s2 (a team of two);
# 4 two s2 (a team of two of the same skill); 5 has duration 0 (dropped, bridged); 6
# needs no skill (a pure delay). Precedences: 1 -> 2, 3; 2 -> 4; 3 -> 5 -> 6 -> 7; 4 -> 7.
DZN = """% a hand-written project
mint = 3;
% maxt = 20;
nActs = 7;
dur = [0, 2, 3, 1, 0, 2, 0];
nSkills = 2;
sreq = [| 0,0,
	| 1,0,
	| 1,1,
	| 0,2,
	| 1,0,
	| 0,0,
	| 0,0, |];
nResources = 3;
mastery = [| true,false,
	| true,true,
	| false,true, |];
nPrecs = 7;
pred = [1,1,2,3,5,6,4];
succ = [2,3,4,5,6,7,7];
USEFUL_RES = [{}, {1,2}, {1,2,3}, {2,3}, {1,2}, {}, {}];
"""


def project() -> Project:
    return parse_project("tiny", DZN)


def test_parse_dzn_reads_numbers_booleans_arrays_and_skips_comments() -> None:
    values = parse_dzn(DZN)
    assert values["nActs"] == 7 and values["mint"] == 3 and "maxt" not in values
    assert values["dur"] == [0, 2, 3, 1, 0, 2, 0]
    assert values["mastery"] == [[True, False], [True, True], [False, True]]
    assert values["sreq"][3] == [0, 2]  # type: ignore[index]
    assert isinstance(values["USEFUL_RES"], str)  # derived sets: kept as text, unused


def test_project_keeps_the_file_as_it_is() -> None:
    p = project()
    assert (p.n_activities, p.n_skills, p.n_resources) == (7, 2, 3)
    assert p.durations[2] == 3 and p.requirements[2] == (1, 1)
    assert p.precedences[0] == (1, 2) and p.precedences[-1] == (4, 7)


def test_instance_teams_skills_and_precedence() -> None:
    instance = project_instance(project())
    by_id = {t.id: t for t in instance.tasks}
    # the dummies (1, 7) and the zero-duration activity 5 are dropped
    assert sorted(by_id) == [2, 3, 4, 6]
    assert instance.timed and instance.has_teams
    # one unit of one skill: a plain one-robot task with that feature
    assert by_id[2].team is None and by_id[2].features == ("s1",)
    assert by_id[3].team == {"s1": 1, "s2": 1}
    assert by_id[4].team == {"s2": 2}
    assert by_id[4].duration == 1.0
    # 5 is bridged: 6 comes after 3 (5's predecessor); nothing after the dropped start
    assert by_id[6].after == (3,) and by_id[2].after == () and by_id[4].after == (2,)
    names = [r.name for r in instance.robots]
    assert names == ["r1", "r2", "r3", "wait6"]
    assert [r.skills for r in instance.robots[:3]] == [("s1",), ("s1", "s2"), ("s2",)]
    # success is flat: 1.0 on a robot's skills, 0.0 elsewhere
    assert instance.robots[0].success == {"s1": 1.0, "s2": 0.0, "wait6": 0.0}
    # the pure delay has a robot of its own, which nothing else may take
    assert by_id[6].features == ("wait6",) and instance.robots[3].skills == ("wait6",)
    eligible = instance.eligible
    assert eligible[3].tolist() == [False, False, False, True]
    assert eligible[0].tolist() == [True, True, False, False]


def test_a_team_the_fleet_cannot_staff_is_refused_by_the_domain() -> None:
    text = DZN.replace("| 0,2,", "| 0,3,")  # three s2 units, two robots have s2
    with pytest.raises(DomainError, match="distinct robots covering 's2'"):
        project_instance(parse_project("short", text))


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("dur = [0, 2, 3, 1, 0, 2, 0]", "dur = [0, 2, 3, 1, 0, 2]", "'dur' must list 7"),
        ("| 0,0, |];\nnResources", "|];\nnResources", "'sreq' must be a 7 x 2"),
        ("| false,true, |]", "| false,1, |]", "'mastery' must hold true or false"),
        ("succ = [2,3,4,5,6,7,7]", "succ = [2,3,4,5,6,7,8]", "activities 1 to 7"),
        ("nPrecs = 7", "nPrecs = 6", "each list 6 activities"),
        ("mint = 3;", "mint = 3x;", "mint: '3x' is not an integer"),
        ("mint = 3;", "mint 3;", "cannot read the statement"),
    ],
)
def test_bad_files_name_what_does_not_fit(old: str, new: str, message: str) -> None:
    assert old in DZN
    with pytest.raises(ValueError, match=message):
        parse_project("bad", DZN.replace(old, new))


def test_a_precedence_cycle_is_refused() -> None:
    text = DZN.replace("pred = [1,1,2,3,5,6,4]", "pred = [1,1,2,3,5,6,6]").replace(
        "succ = [2,3,4,5,6,7,7]", "succ = [2,3,4,5,6,7,5]"
    )
    with pytest.raises(ValueError, match="cycle"):
        parse_project("cycle", text)


def test_published_results_row_k_is_instance_k(tmp_path: Path) -> None:
    folder = tmp_path / RESULTS_2C
    folder.mkdir(parents=True)
    (folder / "results_set2c_g1_pris.txt").write_text(
        "instNum,optimal,LB,makespan,firstSol,UB\n0,1,18,25,28,51\n0,0,18,31,31,51"
    )
    got = published_results(tmp_path)
    assert got["inst_set2c_g1_00"].makespan == 25 and got["inst_set2c_g1_00"].proven
    assert got["inst_set2c_g1_01"].makespan == 31 and not got["inst_set2c_g1_01"].proven
    (folder / "results_set2c_g2_pris.txt").write_text("instNum,optimal\n0,1")
    with pytest.raises(ValueError, match="row 2 lacks"):
        published_results(tmp_path)


def test_local_copy_from_the_option_or_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("LTAA_MSPSP_DIR", raising=False)
    assert local_copy(None) is None
    assert local_copy(str(tmp_path)) is None  # no set 2c inside
    (tmp_path / SET_2C).mkdir(parents=True)
    (tmp_path / SET_2C / "inst_set2c_a_n20_00.dzn").write_text(DZN)
    (tmp_path / SET_2C / "inst_set2c_b_n30_00.dzn").write_text(DZN)
    monkeypatch.setenv("LTAA_MSPSP_DIR", str(tmp_path))
    assert local_copy(None) == tmp_path
    assert [p.name for p in set_2c(tmp_path, "*_n20_*")] == ["inst_set2c_a_n20_00.dzn"]


def test_section_without_a_local_copy_says_skipped(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("LTAA_MSPSP_DIR", raising=False)
    text = section(None)
    assert text.startswith("## Multi-skill project scheduling")
    assert "Skipped: no local copy" in text and "LTAA_MSPSP_DIR" in text


# -- the plan check and the plain model, against a brute force --------------------------------


def feasible_plan() -> tuple[dict[int, float], dict[int, list[tuple[int, int]]]]:
    # 2 on r1 (s1) [0,2); 3 on r2 (s1) + r3 (s2) [0,3); 4 on r2 + r3 (s2) [3,4); 6 [3,5)
    starts = {2: 0.0, 3: 0.0, 4: 3.0, 6: 3.0}
    members = {2: [(0, 0)], 3: [(1, 0), (2, 1)], 4: [(1, 1), (2, 1)], 6: []}
    return starts, members


def test_plan_problems_accepts_a_feasible_plan() -> None:
    starts, members = feasible_plan()
    assert plan_problems(project(), starts, members) == []


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda s, m: s.update({4: 1.0}), "activity 4 starts at 1, before 2 ends"),
        (lambda s, m: s.update({6: 2.0}), "activity 6 starts at 2, before 5 ends"),
        (lambda s, m: m.update({4: [(1, 1), (1, 1)]}), "a resource contributes twice"),
        (lambda s, m: m.update({2: [(2, 0)]}), "resource 3 has not mastered skill 1"),
        (lambda s, m: m.update({4: [(2, 1)]}), "skills covered [0, 1], required [0, 2]"),
        (lambda s, m: m.update({2: [(1, 0)]}), "resource 2 works on activities 2 and 3"),
        (lambda s, m: s.pop(3), "activity 3 has no start"),
    ],
)
def test_plan_problems_names_each_broken_rule(change, message) -> None:  # type: ignore[no-untyped-def]
    starts, members = feasible_plan()
    change(starts, members)
    assert any(message in p for p in plan_problems(project(), starts, members))


def brute_force_makespan(p: Project) -> int:
    """Serial schedule generation over every precedence-feasible activity order and every
    choice of members: some order and team choice builds an optimal schedule (a regular
    objective), so the least makespan over all of them is the optimum."""
    acts = [a for a in range(1, p.n_activities + 1) if p.durations[a - 1] > 0]
    teams = {a: _teams(p, a) for a in acts}
    best = sum(p.durations)
    for order in itertools.permutations(acts):
        for choice in itertools.product(*(teams[a] for a in order)):
            best = min(best, _serial(p, order, choice))
    return best


def _teams(p: Project, a: int) -> list[tuple[int, ...]]:
    need = [s for s, n in enumerate(p.requirements[a - 1]) for _ in range(n)]
    out = set()
    for robots in itertools.permutations(range(p.n_resources), len(need)):
        if all(p.mastery[r][s] for r, s in zip(robots, need, strict=True)):
            out.add(tuple(sorted(robots)))
    return sorted(out)


def _serial(p: Project, order: tuple[int, ...], choice: tuple[tuple[int, ...], ...]) -> int:
    end: dict[int, int] = {}
    free = [0] * p.n_resources

    def ready(a: int) -> int:  # the latest end among predecessors, through dropped ones
        times = [0]
        for b, c in p.precedences:
            if c == a:
                times.append(end[b] if b in end else ready(b))
        return max(times)

    for a, team in zip(order, choice, strict=True):
        if any(b not in end and p.durations[b - 1] > 0 for b, c in _closure(p, a)):
            return sum(p.durations) + 1  # an order against the precedences
        start = max([ready(a), *(free[r] for r in team)])
        end[a] = start + p.durations[a - 1]
        for r in team:
            free[r] = end[a]
    return max(end.values())


def _closure(p: Project, a: int) -> list[tuple[int, int]]:
    direct = [(b, c) for b, c in p.precedences if c == a]
    return direct + [e for b, _ in direct for e in _closure(p, b)]


def test_plain_model_equals_the_brute_force() -> None:
    p = project()
    # 3 needs r2 or r1 (s1) and r2 or r3 (s2); 4 needs r2 and r3: 3 and 4 are serial
    want = brute_force_makespan(p)
    got = plain_model(p, time_limit_s=10)
    assert got["status"] == "optimal" and got["makespan"] == want == 5


def test_schedule_method_proves_the_brute_force_optimum_and_passes_both_checks() -> None:
    """The benchmark's whole path on the tiny project: `schedule` on the team instance, its
    plan read back per activity and checked against the `.dzn` data."""
    got = solve_schedule_method(project(), 5.0)
    assert got["status"] == "optimal", got
    assert got["makespan"] == got["checked_makespan"] == brute_force_makespan(project())
    assert got["problems"] == []


def test_problem_is_the_makespan_without_a_cap() -> None:
    problem = problem_of(project())
    assert problem.objective.kind.value == "makespan"
    assert problem.cap.max_deviation is None


def test_the_section_flags_a_false_optimal_loudly() -> None:
    def row(name: str, status: str, makespan: float, problems: list[str]) -> dict:
        return {
            "name": name,
            "tasks": 20,
            "teams": 9,
            "robots": 4,
            "published": {"makespan": 25, "proven": True},
            "schedule": {
                "status": status,
                "makespan": makespan,
                "bound": 25.0 if status == "optimal" else 24.0,
                "wall_s": 1.0,
                "cpu_s": 1.0,
                "wall_cut": False,
                "problems": problems,
            },
            "plain": {"status": "optimal", "makespan": 25},
        }

    rows = [
        row("inst_set2c_a_00", "optimal", 25, []),
        row("inst_set2c_b_00", "optimal", 26, []),
        row("inst_set2c_c_00", "feasible", 25, ["resource 1 works on 2 and 3 at once"]),
    ]
    text = body(rows, "a test", "img/x.png")
    assert "**FALSE OPTIMAL on 1: inst_set2c_b_00**" in text
    assert "reached on 2 of 3 instances run (**missed**)" in text
    assert "proven optimal on 2 of 3 (at least two thirds: met)" in text
    assert "break the MSPSP's rules (independent check):** inst_set2c_c_00" in text
    assert "26 **FALSE OPTIMAL**" in text and "25 **INFEASIBLE**" in text
    assert "plain model proves and `schedule` does not:** inst_set2c_c_00" in text
    assert text.rstrip().endswith("(img/x.png)")


def test_cpu_figure_is_written(tmp_path: Path) -> None:
    from benchmarks.mspsp_bench import cpu_figure

    rows = [
        {
            "published": {"makespan": 25},
            "schedule": {"status": s, "makespan": m, "cpu_s": 0.5},
            "plain": {"cpu_s": 0.2},
        }
        for s, m in (("optimal", 25), ("feasible", 25), ("feasible", 27), ("refused", 0))
    ]
    assert cpu_figure(rows, tmp_path) == "img/mspsp_set2c_cpu.png"
    assert (tmp_path / "mspsp_set2c_cpu.png").read_bytes()[:4] == b"\x89PNG"


def test_measure_keeps_each_row_and_a_resumed_run_measures_only_the_rest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from benchmarks import mspsp_bench

    (tmp_path / SET_2C).mkdir(parents=True)
    (tmp_path / RESULTS_2C).mkdir(parents=True)
    for group in ("g1", "g2"):
        (tmp_path / SET_2C / f"inst_set2c_{group}_00.dzn").write_text(DZN)
        (tmp_path / RESULTS_2C / f"results_set2c_{group}_pris.txt").write_text(
            "instNum,optimal,LB,makespan\n0,1,3,5"
        )
    kept = tmp_path / "kept.json"
    monkeypatch.setattr(mspsp_bench, "RESULTS", kept)
    first = mspsp_bench.measure(tmp_path, "*_g1_*", None)
    assert [r["name"] for r in first] == ["inst_set2c_g1_00"]
    assert first[0]["schedule"]["makespan"] == first[0]["plain"]["makespan"] == 5
    marked = dict(first[0], load=-1.0)  # a row measured "before": reused as it is
    kept.write_text(json.dumps([marked]))
    monkeypatch.setenv("MSPSP_REUSE", "1")
    both = mspsp_bench.measure(tmp_path, "*", None)
    assert [r["name"] for r in both] == ["inst_set2c_g1_00", "inst_set2c_g2_00"]
    assert both[0]["load"] == -1.0 and both[1]["load"] >= 0
    assert [r["name"] for r in json.loads(kept.read_text())] == [r["name"] for r in both]


def minizinc_output(starts: list[int], pairs: dict[int, list[tuple[int, int]]]) -> str:
    """A full-output text as the library's MiniZinc runs print it: solutions separated by
    `----------`, contrib[ACT, RESOURCE, SKILL] flattened row-major."""
    flags = [
        "true" if (r, s) in pairs.get(a, []) else "false"
        for a in range(1, 8)
        for r in range(3)
        for s in range(2)
    ]
    return (
        f"makespan = {max(starts)}\nstart times = [{', '.join(map(str, starts))}]\n"
        f"assignment = [false]\ncontribution = [{', '.join(flags)}]\n"
    )


def test_the_librarys_own_plan_is_read_and_checked(tmp_path: Path) -> None:
    from benchmarks.mspsp import OUTPUT_2C, published_output, published_plan

    _, members = feasible_plan()
    worse = minizinc_output([0, 0, 2, 5, 5, 5, 7], members)  # a first, longer solution
    best = minizinc_output([0, 0, 0, 3, 3, 3, 5], members)
    text = worse + "----------\n% time elapsed: 1 ms\n" + best + "----------\n==========\n"
    starts, got = published_plan(project(), text)
    assert starts == {2: 0.0, 3: 0.0, 4: 3.0, 6: 3.0}
    assert got == members
    assert plan_problems(project(), starts, got) == []
    with pytest.raises(ValueError, match="no solution"):
        published_plan(project(), "=====UNKNOWN=====")
    (tmp_path / OUTPUT_2C).mkdir(parents=True)
    (tmp_path / OUTPUT_2C / "full-output_set2c_g1_pris_01.txt").write_text(text)
    assert published_output(tmp_path, "inst_set2c_g1_01") == text
    assert published_output(tmp_path, "inst_set2c_g1_00") is None
