"""An offline chain check run on an export as a reader runs it: another Python process, in
the repository (the checks import app.store.chain from this checkout), with nothing of the
test's environment but the path."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CHECK_TRACE = ROOT / "scripts" / "check_trace.py"


def check_offline(
    export: Path, *keys: Path, script: Path = CHECK_TRACE
) -> subprocess.CompletedProcess[str]:
    """`script` (scripts/check_trace.py, or the docs' snippet saved as a file) on `export`,
    with the public key files `keys` if any."""
    return subprocess.run(
        [sys.executable, str(script), str(export), *map(str, keys)],
        cwd=ROOT,
        env={"PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=120,
    )
