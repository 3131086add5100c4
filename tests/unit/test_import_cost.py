"""Starting the server imports only what serving needs: every server start (and every
end-to-end test's restart after a SIGKILL) pays for the rest. scipy.stats (about a second)
is for the estimates' intervals, OR-Tools' CP-SAT (half a second) for schedules; both are
imported where they are used."""

from __future__ import annotations

import json
import subprocess
import sys

HEAVY = ("scipy.stats", "ortools.sat.python.cp_model", "sklearn", "torch", "matplotlib")


def test_the_server_module_imports_none_of_the_heavy_libraries() -> None:
    probe = (
        f"import json, sys, app.main; print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=120
    )
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
