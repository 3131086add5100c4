"""House rules that a review would otherwise have to catch by eye (docs/development.md):
no function over 100 lines and no module over 450 lines in app/ and benchmarks/."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("app", "benchmarks")
MAX_FUNCTION_LINES = 100
MAX_MODULE_LINES = 450


def _modules() -> list[Path]:
    return sorted(p for package in PACKAGES for p in (ROOT / package).rglob("*.py"))


def long_functions(path: Path, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """`path:name (n lines)` for each function (nested and methods too) longer than
    limit, counted from its `def` line to its last line."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            lines = (node.end_lineno or node.lineno) - node.lineno + 1
            if lines > limit:
                out.append(f"{path.relative_to(ROOT)}:{node.name} ({lines} lines)")
    return out


def test_the_check_sees_a_long_function(tmp_path: Path) -> None:
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    source = tmp_path / "long.py"
    source.write_text(f"def short() -> None:\n    pass\n\n\ndef long() -> None:\n{body}\n")
    global ROOT
    saved, ROOT = ROOT, tmp_path
    try:
        assert long_functions(source) == [f"long.py:long ({MAX_FUNCTION_LINES + 1} lines)"]
    finally:
        ROOT = saved


def test_no_function_is_over_100_lines() -> None:
    modules = _modules()
    assert len(modules) > 50, "the packages were not found"
    found = [f for path in modules for f in long_functions(path)]
    assert found == [], "split these into named steps: " + ", ".join(found)


def test_no_module_is_over_450_lines() -> None:
    found = []
    for path in _modules():
        lines = len(path.read_text(encoding="utf-8").splitlines())
        if lines > MAX_MODULE_LINES:
            found.append(f"{path.relative_to(ROOT)} ({lines} lines)")
    assert found == [], "split these modules: " + ", ".join(found)
