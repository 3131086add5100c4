"""tests/ mirrors app/ (docs/development.md#tests-by-feature): a feature's tests are one folder.

Every folder of tests/ is named for a package of app/ (its unit, API, end-to-end and browser
tests together, the slow ones marked), or is one of the few that are not a feature's: the
project's own checks, the benchmarks', the shared support and the fake servers. And every
package of app/ that holds code has its folder of tests."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
APP = ROOT / "app"
TESTS = ROOT / "tests"
# Not features of app/: checks of the whole repository, of benchmarks/, what tests share.
OWN = {"project", "benchmarks", "support", "fakes"}
# Packages of app/ without tests of their own, and why.
UNTESTED = {"data": "data files read by the domain and the catalog, tested there"}


def _packages(root: Path) -> set[str]:
    return {p.name for p in root.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}


def test_every_test_folder_is_a_package_of_app() -> None:
    strays = _packages(TESTS) - _packages(APP) - OWN
    assert not strays, (
        f"tests/{sorted(strays)} name no package of app/: put each test in the folder of "
        "the feature it tests (tests/<feature>/ for app/<feature>/)"
    )


def test_every_package_of_app_has_its_tests() -> None:
    missing = _packages(APP) - _packages(TESTS) - set(UNTESTED)
    assert not missing, f"app/{sorted(missing)} have no tests/<feature>/ folder"


def test_no_tests_outside_the_feature_folders() -> None:
    loose = sorted(p.name for p in TESTS.glob("test_*.py"))
    assert not loose, f"{loose} sit at the top of tests/: move them into their feature's folder"


def test_support_holds_no_tests() -> None:
    tests = sorted(p.name for p in (TESTS / "support").glob("test_*.py"))
    assert not tests, f"tests/support/ is shared code, not tests: move {tests}"
