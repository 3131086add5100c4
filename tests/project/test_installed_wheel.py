"""The built wheel serves as the container image serves it: installed (not editable) into a
fresh virtualenv, started by scripts/serve.sh from a directory outside the checkout, the
app finds its migrations, migrates a fresh store, answers /health and an allocation.

Cheap on purpose (CI's CPU is shared): the fresh venv has no pip and no copy of the
dependencies; a .pth line puts the shared venv's site-packages after its own, and the
wheel goes in with --no-deps. That line adds the directory only: the .pth files in it
(the shared venv's editable finder, which points at a checkout) are not run, so `app` can
only come from the wheel; the test checks that too.
"""

from __future__ import annotations

import shutil
import sqlite3
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import httpx
import pytest

from app.store.migrate import MIGRATIONS
from tests.support.polling import eventually
from tests.support.server import LISTENING, PORT_TAKEN, ROOT, free_port

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(300)]

# What the wheel is built from: the files pyproject.toml packages, as a clean clone has them.
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "app", "benchmarks")


def _build_wheel(work: Path) -> Path:
    src = work / "src"
    src.mkdir()
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, src / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(ROOT / name, src / name)
    dist = work / "dist"
    # The PEP 517 hook pip would call, without pip's isolated build environment (which
    # would download setuptools): the shared venv has the setuptools pyproject.toml asks for.
    built = subprocess.run(
        [
            sys.executable,
            "-I",
            "-c",
            "import sys; from setuptools import build_meta as b; print(b.build_wheel(sys.argv[1]))",
            str(dist),
        ],
        cwd=src,
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
    )
    assert built.returncode == 0, built.stdout[-2000:] + built.stderr[-3000:]
    return dist / built.stdout.split()[-1]


def _fresh_venv(venv: Path, wheel: Path) -> Path:
    subprocess.run(
        [sys.executable, "-I", "-m", "venv", "--without-pip", str(venv)], check=True, timeout=60
    )
    python = venv / "bin" / "python"
    site = Path(
        subprocess.run(
            [str(python), "-I", "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    )
    (site / "shared_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    # The shared venv's pip, installing into the fresh venv (its scripts, its shebangs).
    subprocess.run(
        [
            sys.executable,
            "-I",
            "-m",
            "pip",
            "--python",
            str(python),
            "install",
            "--quiet",
            "--no-deps",
            "--no-compile",
            "--no-index",
            str(wheel),
        ],
        check=True,
        timeout=120,
    )
    # uvicorn is a dependency, so its script is the shared venv's; the image's venv has its
    # own, which serve.sh finds on PATH. This one runs the fresh venv's interpreter.
    uvicorn = venv / "bin" / "uvicorn"
    uvicorn.write_text(f"#!{python} -I\nfrom uvicorn.main import main\nmain()\n")
    uvicorn.chmod(0o755)
    return python


def _serve(srv: Path, venv: Path, data: Path) -> tuple[subprocess.Popen[bytes], str, Path]:
    """sh scripts/serve.sh in `srv`, as the image's CMD runs it: the venv first on PATH, and
    nothing of the developer's environment (no PYTHONPATH pointing at a checkout)."""
    log = srv / "server.log"
    for _ in range(5):
        port = free_port()
        env = {
            "PATH": f"{venv / 'bin'}:/usr/bin:/bin",
            "HOME": str(srv),
            "LTAA_DATA_DIR": str(data),
            "HOST": "127.0.0.1",
            "PORT": str(port),
        }
        with log.open("wb") as out:
            proc = subprocess.Popen(
                ["sh", "scripts/serve.sh"], cwd=srv, env=env, stdout=out, stderr=subprocess.STDOUT
            )
        url = f"http://127.0.0.1:{port}"

        def state(proc: subprocess.Popen[bytes] = proc, port: int = port) -> str:
            logged = log.read_text()
            if proc.poll() is not None:
                return "taken" if PORT_TAKEN in logged else "exited"
            return "up" if LISTENING.format(port=port) in logged else "starting"

        now = eventually(
            state,
            until=lambda s: s != "starting",
            timeout=120,
            interval=0.1,
            what="the installed server listening",
            context=lambda: log.read_text()[-3000:],
        )
        if now == "up":
            return proc, url, log
        assert now == "taken", f"the installed server exited:\n{log.read_text()[-3000:]}"
    raise AssertionError("five ports in a row were taken before the server bound them")


def test_the_wheel_installed_outside_the_checkout_migrates_and_serves(tmp_path: Path) -> None:
    wheel = _build_wheel(tmp_path)
    names = zipfile.ZipFile(wheel).namelist()
    revisions = sorted(p.name for p in (MIGRATIONS / "versions").glob("*.py"))
    assert "app/store/migrations/env.py" in names
    assert "app/store/migrations/script.py.mako" in names
    assert (
        sorted(n.rsplit("/", 1)[1] for n in names if n.startswith("app/store/migrations/versions/"))
        == revisions
    )

    venv = tmp_path / "venv"
    python = _fresh_venv(venv, wheel)
    srv = tmp_path / "srv"  # the image's WORKDIR: only the start script, no source tree
    (srv / "scripts").mkdir(parents=True)
    shutil.copy2(ROOT / "scripts" / "serve.sh", srv / "scripts" / "serve.sh")

    imported = subprocess.run(
        [str(python), "-I", "-c", "import app, uvicorn; print(app.__file__)"],
        cwd=srv,
        env={"PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    assert Path(imported).is_relative_to(venv), imported
    assert not Path(imported).is_relative_to(ROOT), imported

    data = tmp_path / "data"
    proc, url, log = _serve(srv, venv, data)
    try:
        with httpx.Client(base_url=url, timeout=30) as http:
            assert http.get("/health").status_code == 200
            answer = http.post("/allocate", json={"solver": "dp", "scenario": "baseline"})
            assert answer.status_code == 200, answer.text
            assert answer.json()["assignments"]
    finally:
        proc.terminate()
        proc.wait(timeout=30)

    head = max(revisions)  # the files are numbered in chain order
    head_id = next(
        line.split("=", 1)[1].strip().strip("'\"")
        for line in (MIGRATIONS / "versions" / head).read_text().splitlines()
        if line.startswith("revision =")
    )
    with sqlite3.connect(data / "ltaa.db") as db:
        (version,) = db.execute("SELECT version_num FROM alembic_version").fetchone()
        tables = {row[0] for row in db.execute("SELECT name FROM sqlite_master")}
    assert version == head_id, log.read_text()[-3000:]
    assert {"runs", "decisions", "run_events"} <= tables
