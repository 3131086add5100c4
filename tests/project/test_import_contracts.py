"""The layering in pyproject.toml's [tool.importlinter] holds, so `pytest` alone enforces it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# import-linter ships no `python -m` entry; this is what its `lint-imports` script runs.
LINT_IMPORTS = "from importlinter.cli import lint_imports_command; lint_imports_command()"


def test_the_import_contracts_are_kept() -> None:
    # A subprocess from the repo root: lint-imports reads ./pyproject.toml and puts the cwd
    # on sys.path, so it analyses this checkout's `app`, not an installed copy.
    result = subprocess.run(
        [sys.executable, "-c", LINT_IMPORTS, "--no-cache", "--no-logo"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0 broken" in result.stdout


def _lint_copy(tree: Path) -> subprocess.CompletedProcess[str]:
    """lint-imports over a broken copy of the app in `tree` (only that copy on the path)."""
    return subprocess.run(
        [sys.executable, "-c", LINT_IMPORTS, "--no-cache", "--no-logo"],
        cwd=tree,
        capture_output=True,
        text=True,
        timeout=120,
        env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(tree)},
    )


def _acyclic_contract() -> str:
    """This project's acyclic-siblings contract, as pyproject.toml states it."""
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    (contract,) = [c for c in config["contracts"] if c["type"] == "acyclic_siblings"]
    assert contract["ancestors"] == ["app"]
    return contract["name"]


def test_a_new_import_cycle_breaks_the_contracts(tmp_path: Path) -> None:
    # The contract is only as good as its power to fail: a copy of `app` with one new
    # cycle (two sibling modules importing each other) is refused.
    import shutil

    shutil.copytree(ROOT / "app", tmp_path / "app", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    (tmp_path / "app" / "domain" / "cycle_a.py").write_text("from app.domain import cycle_b\n")
    (tmp_path / "app" / "domain" / "cycle_b.py").write_text("from app.domain import cycle_a\n")
    result = _lint_copy(tmp_path)
    assert result.returncode != 0
    assert f"{_acyclic_contract()} BROKEN" in " ".join(result.stdout.split())
    assert "cycle_a" in result.stdout and "cycle_b" in result.stdout


def _contract_named(start: str) -> str:
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    (name,) = [c["name"] for c in config["contracts"] if c["name"].startswith(start)]
    return str(name)


def test_a_feature_importing_endpoints_or_the_app_importing_benchmarks_breaks_them(
    tmp_path: Path,
) -> None:
    # The slices' contracts fail too: a feature importing another feature's endpoints (only
    # app.api mounts them), and an app module importing the benchmarks.
    import shutil

    shutil.copytree(ROOT / "app", tmp_path / "app", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "benchmarks" / "__init__.py").write_text("")
    (tmp_path / "benchmarks" / "report.py").write_text("")
    (tmp_path / "app" / "sites" / "peek.py").write_text("from app.runs import endpoints\n")
    (tmp_path / "app" / "cli" / "measure.py").write_text("from benchmarks import report\n")
    result = _lint_copy(tmp_path)
    assert result.returncode != 0
    out = " ".join(result.stdout.split())
    assert f"{_contract_named('A feature')} BROKEN" in out
    assert f"{_contract_named('The app never imports the benchmarks')} BROKEN" in out
    assert "app.sites.peek" in result.stdout and "app.cli.measure" in result.stdout
