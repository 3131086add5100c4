"""Apply the alembic migrations programmatically (before serving, never at import).

The migrations ship inside the package (``app/store/migrations``, package data of the
wheel), so an installed app finds them wherever it is installed: an editable checkout, a
wheel in a virtualenv, the container image. The repository's ``alembic.ini`` points the
``alembic`` command at the same directory for developers (``make migrate``).
"""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config

MIGRATIONS = Path(__file__).resolve().parent / "migrations"


def alembic_config(database_url: str) -> Config:
    # No ini file: the installed app has none, and alembic.ini holds only the developers'
    # script location and logging (env.py never reads the logging sections).
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    cfg.set_main_option("path_separator", "os")
    cfg.set_main_option("sqlalchemy.url", database_url.replace("%", "%%"))
    return cfg


def upgrade_head(database_url: str) -> None:
    command.upgrade(alembic_config(database_url), "head")
