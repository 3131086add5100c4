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
