"""Alembic environment: the app tables only (the checkpointer manages its own).

The revision files in versions/ are numbered in chain order: a file's number is its place
in the chain (0001 first, each file's down_revision the file before it). The revision ids
inside them are what every existing database records in alembic_version, so they are never
renamed, even where an id carries an older number than its file
(versions/0006_reviews_annotations.py holds revision "0007_reviews_annotations"). A new
revision takes the next number as its id: `alembic revision --rev-id <number> -m "what it
adds"` writes the file versions/<number>_<what it adds>.py.
"""

from __future__ import annotations

from typing import Any

from alembic import context
from sqlalchemy import text

from app.store import fleet_models, site_models, webhook_models  # noqa: F401  (registers their tables)
from app.store.db import make_engine
from app.store.models import Base

config = context.config

# Any constant shared by every process of the service: two replicas starting together on
# one PostgreSQL database must not both create alembic_version or run the same step.
MIGRATION_LOCK_KEY = 0x4C544141  # "LTAA"


def _url() -> str:
    url = config.get_main_option("sqlalchemy.url")
    if url:
        return url
    from app.config import get_settings

    return get_settings().db_url


def _include_name(name: str | None, type_: str, _parents: Any) -> bool:
    # On PostgreSQL the LangGraph checkpointer's tables share the database; they are its
    # own business, so autogenerate and `alembic check` must not see them.
    return type_ != "table" or name in Base.metadata.tables


def run_migrations_offline() -> None:
    context.configure(
        url=_url(),
        target_metadata=Base.metadata,
        literal_binds=True,
        render_as_batch=True,
        include_name=_include_name,
    )
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_online() -> None:
    engine = make_engine(_url())
    with engine.connect() as connection:
        context.configure(
            connection=connection,
            target_metadata=Base.metadata,
            render_as_batch=True,
            include_name=_include_name,
        )
        with context.begin_transaction():
            if connection.dialect.name == "postgresql":
                # Held until this transaction commits (PostgreSQL DDL is transactional).
                connection.execute(
                    text("SELECT pg_advisory_xact_lock(:key)"), {"key": MIGRATION_LOCK_KEY}
                )
            context.run_migrations()
    engine.dispose()


if context.is_offline_mode():
    run_migrations_offline()
else:
    run_migrations_online()
