"""The migration files have one unambiguous order, and stores upgrade through it.

The files are numbered in chain order; the revision ids inside them are what existing
databases record in alembic_version, so every id a store may hold must still be found,
and a store at any of them must reach the head.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from alembic import command
from alembic.script import ScriptDirectory
from sqlalchemy import text

from app.store.db import make_engine
from app.store.migrate import MIGRATIONS, alembic_config, upgrade_head

# Every revision id a store written by an earlier release may record, in chain order.
# History: never edit an entry (a new revision is appended after the last).
RECORDED = [
    "0001",
    "0002",
    "0003",
    "0004",
    "0005",
    "0007_reviews_annotations",
    "0008_reviews",
    "0006_revisions",
    "0009",
    "0008_yearlong",
    "0010_sites",
    "0011_times",
    "0012_unmeasured",
    "0013_decision_team",
    "0014_site_report_members",
]


def _chain() -> list[str]:
    script = ScriptDirectory.from_config(alembic_config("sqlite://"))
    assert len(script.get_bases()) == 1 and len(script.get_heads()) == 1, "one line, no branch"
    return [rev.revision for rev in reversed(list(script.walk_revisions()))]


def test_the_file_numbers_are_the_chain_order() -> None:
    files = sorted((MIGRATIONS / "versions").glob("*.py"))
    numbers = [int(re.match(r"(\d{4})_", f.name).group(1)) for f in files]  # type: ignore[union-attr]
    assert numbers == list(range(1, len(files) + 1)), "numbered 0001, 0002, ... with no repeat"
    script = ScriptDirectory.from_config(alembic_config("sqlite://"))
    in_files = [
        next(r.revision for r in script.walk_revisions() if Path(r.path).name == f.name)
        for f in files
    ]
    assert in_files == _chain()


def test_every_recorded_revision_is_still_known_in_its_place() -> None:
    assert _chain()[: len(RECORDED)] == RECORDED


@pytest.mark.parametrize("recorded", ["0008_reviews", "0008_yearlong", "0011_times"])
def test_a_store_at_a_recorded_revision_upgrades_to_the_head(tmp_path: Path, recorded: str) -> None:
    url = f"sqlite:///{tmp_path / 'app.db'}"
    command.upgrade(alembic_config(url), recorded)
    upgrade_head(url)
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            current = conn.execute(text("SELECT version_num FROM alembic_version")).scalar_one()
    finally:
        engine.dispose()
    assert current == _chain()[-1]
    command.check(alembic_config(url))  # the upgraded store matches the models
