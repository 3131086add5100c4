"""Starting the server imports only what serving needs: every server start (and every
end-to-end test's restart after a SIGKILL) pays for the rest. scipy.stats (about a second)
is for the estimates' intervals, OR-Tools' CP-SAT (half a second) for schedules; both are
imported where they are used. The served module (app/asgi.py) imports the app with the
cyclic garbage collector paused (about a fifth of the import's CPU) and freezes what the
import made; the collector must be running again when it is done."""

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


def test_the_served_module_imports_the_app_with_the_collector_paused_then_running() -> None:
    probe = """
import gc, json
full = []
def watch(phase, info):
    if phase == "start" and info["generation"] == 2:
        full.append(info)
gc.callbacks.append(watch)
import app.asgi
gc.callbacks.remove(watch)
print(json.dumps([gc.isenabled(), gc.get_freeze_count(), len(full)]))
"""
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=120
    )
    enabled, frozen, full_collections = json.loads(out.stdout.strip().splitlines()[-1])
    assert enabled is True  # the runs' garbage is still collected
    assert frozen > 100_000  # the import's objects sit in the permanent generation
    assert full_collections == 0  # none walked them while they were being made
