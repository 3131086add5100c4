"""Every name of the app's code a docstring cites exists: a renamed module or a deleted
class leaves no docstring pointing at it (docs/development.md#where-things-live).

Three forms are read in every module, class and function docstring of app/:
- a dotted name from the root, `app.runs.recorder.Fence`: the longest prefix that
  imports is the module, the rest are attributes (a class's annotated or pydantic field
  counts);
- a file path ending in `.py` (`graph/recorder.py`, `scripts/check_trace.py`): it exists
  under the repository, under app/, beside the module, or in an installed package;
- a sibling module's name, `outbox.enqueue_for_event` in a module beside outbox.py: it
  resolves in the package, unless the first part is a parameter of the documented
  function (`context.reasoner`).
"""

from __future__ import annotations

import ast
import importlib
import re
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[2]
APP = ROOT / "app"

FROM_ROOT = re.compile(r"(?<![\w.])app(?:\.\w+)+")
PY_PATH = re.compile(r"(?<![\w./-])((?:[\w.-]+/)*\w+\.py)\b")
DOTTED = re.compile(r"(?<![\w.])([a-z_]\w*(?:\.[A-Za-z_]\w*)+)")
# A dotted token that is a file name or a host, not a module's attribute.
NOT_CODE = re.compile(r"\.(?:py|md|json|svg|png|csv|ics|xml|xer|mpp|txt|toml|yaml|com|org)$")

Documented = ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef


def _import(name: str) -> ModuleType | None:
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as error:
        if error.name is not None and name.startswith(error.name):
            return None  # the module itself is missing, not something it imports
        raise


def resolves(dotted: str) -> bool:
    """Whether `dotted` names a module, or an attribute (or a declared field) of one."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        module = _import(".".join(parts[:cut]))
        if module is not None:
            break
    else:
        return False
    target: object = module
    for part in parts[cut:]:
        if hasattr(target, part):
            target = getattr(target, part)
            continue
        declared = getattr(target, "__annotations__", {}) | getattr(target, "model_fields", {})
        return isinstance(target, type) and part in declared
    return True


def _installed(path: str) -> bool:
    return any((Path(entry) / path).exists() for entry in sys.path if entry)


def path_exists(path: str, beside: Path) -> bool:
    return any((base / path).exists() for base in (ROOT, APP, beside)) or _installed(path)


def _documented(tree: ast.Module) -> Iterator[tuple[Documented, str]]:
    for node in ast.walk(tree):
        if isinstance(node, Documented):
            doc = ast.get_docstring(node)
            if doc:
                yield node, doc


def _parameters(node: Documented) -> set[str]:
    if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
        args = node.args
        return {a.arg for a in [*args.posonlyargs, *args.args, *args.kwonlyargs]}
    return set()


def stale_names(path: Path, package: str, beside: Path | None = None) -> list[str]:
    """`where: name` for each name cited in a docstring of `path` that does not resolve;
    `package` is the dotted package of the folder `beside` (the module's own by default)
    whose modules are its siblings."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    beside = beside or path.parent
    siblings = {p.stem for p in beside.glob("*.py")} - {"__init__"}
    where = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path.name
    out = []
    for node, doc in _documented(tree):
        label = f"{where}:{getattr(node, 'name', '<module>')}"
        for match in FROM_ROOT.finditer(doc):
            if not resolves(match.group(0)):
                out.append(f"{label}: {match.group(0)}")
        for match in PY_PATH.finditer(doc):
            if not path_exists(match.group(1), beside):
                out.append(f"{label}: {match.group(1)}")
        shadowed = _parameters(node)
        for match in DOTTED.finditer(doc):
            name = match.group(1)
            head = name.split(".")[0]
            if head not in siblings or head in shadowed or NOT_CODE.search(name):
                continue
            if not resolves(f"{package}.{name}"):
                out.append(f"{label}: {name}")
    return out


def _package(path: Path) -> str:
    return ".".join(path.parent.relative_to(ROOT).parts)


def test_the_check_sees_each_form(tmp_path: Path) -> None:
    source = tmp_path / "probe.py"
    source.write_text(
        '"""Cites app.runs.recorder.Fence, app.runs.recorder.StatusFence, runs/recorder.py,\n'
        'runs/gone.py, recorder.Fence and recorder.Gone."""\n\n\n'
        "def f(recorder: object) -> None:\n"
        '    """recorder.anything is the parameter."""\n',
        encoding="utf-8",
    )
    found = stale_names(source, "app.runs", beside=APP / "runs")
    cited = [f.rsplit(": ", 1)[1] for f in found]
    assert cited == ["app.runs.recorder.StatusFence", "runs/gone.py", "recorder.Gone"]


def test_a_pydantic_field_resolves() -> None:
    assert resolves("app.http.responses.ErrorOut.detail")
    assert not resolves("app.http.responses.ErrorOut.no_such_field")


MODULES = sorted(APP.rglob("*.py"))


@pytest.mark.parametrize("path", MODULES, ids=[str(p.relative_to(ROOT)) for p in MODULES])
def test_every_name_a_docstring_cites_exists(path: Path) -> None:
    found = stale_names(path, _package(path))
    assert found == [], "docstrings cite names that do not exist: " + "; ".join(found)
