"""Fenced upserts: a row of a run's record written in one statement that also checks that
the run still holds (its status is `running`; in scale-out, this process holds its lease),
and that writes nothing when it does not.

Why one statement: the fence used to be its own conditional UPDATE of the run's row before
each write (two, with the lease): three round trips per recorder write, most of a durable
run's overhead. Folded into the write, the fence is as strong as before:

- SQLite: `INSERT ... SELECT :values WHERE EXISTS (the run row as required) ON CONFLICT DO
  UPDATE`. A writing statement takes the database's write lock before it reads, so a
  revision's supersede (which writes the run's row first, in its own transaction) commits
  wholly before this statement or waits for it: never between the check and the write.
- PostgreSQL: the run's row is updated in a data-modifying CTE (row-locked, the lease
  renewed), and the INSERT selects from that CTE, so it writes only if the row matched. The
  row lock serialises with a superseding revision exactly as the separate UPDATE did.

A write that found the fence closed wrote nothing; the caller asks `why_refused` which
fence it was (a rare path, so the diagnosis may cost a query).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from datetime import timedelta
from functools import cache
from typing import Any, cast

from sqlalchemy import Connection, Interval, Table, bindparam, exists, func, select, update
from sqlalchemy import cast as sql_cast
from sqlalchemy.dialects.postgresql import insert as postgresql_insert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert

from app.domain.lifecycle import RunStatus
from app.store.models import Base, Run

# Bind names of the fence's own parameters (no column is so named).
_RUN = "fence_run_id"
_OWNER = "fence_lease_owner"
_LEASE = "fence_lease"
# Values are bound under prefixed names: a parameter named like a column is taken by
# SQLAlchemy as a SET value of the DML statement, the fence's UPDATE of runs included.
_VALUE = "v_"


@dataclass(frozen=True)
class WriteGuard:
    """What a fenced write requires of its run's row."""

    run_id: str
    running: bool = True  # status == 'running' (the status fence)
    lease_owner: str | None = None  # lease_owner == this (the lease fence; PostgreSQL)
    lease_s: float = 0.0  # with lease_owner: the lease is renewed for this long

    def params(self) -> dict[str, Any]:
        out: dict[str, Any] = {_RUN: self.run_id}
        if self.lease_owner is not None:
            out[_OWNER] = self.lease_owner
            out[_LEASE] = timedelta(seconds=self.lease_s)
        return out

    @property
    def shape(self) -> tuple[bool, bool]:
        return self.running, self.lease_owner is not None


@dataclass(frozen=True)
class Written:
    """How a fenced write ended: whether the fence held (and the row was written), and,
    with a lease fence, whether the run's cancel was requested (as the lease's renewal tells)."""

    ok: bool
    cancel_requested: bool = False


def _run_conditions(running: bool, leased: bool) -> list[Any]:
    runs = cast(Table, Run.__table__).c
    where: list[Any] = [runs.id == bindparam(_RUN)]
    if running:
        where.append(runs.status == RunStatus.RUNNING.value)
    if leased:
        where.append(runs.lease_owner == bindparam(_OWNER))
    return where


@cache
def _statement(
    dialect: str,
    model: type[Base],
    names: tuple[str, ...],
    keys: tuple[str, ...],
    shape: tuple[bool, bool],
) -> Any:
    """The fenced upsert of one `model` row with the columns `names` (built once per shape
    and executed with parameters, so SQLAlchemy's compiled cache is hit). A conflict
    updates the given columns but the keys; columns not given keep their stored value."""
    table = cast(Table, model.__table__)
    columns = [table.c[name] for name in names]
    running, leased = shape
    if dialect == "postgresql":
        runs = cast(Table, Run.__table__)
        # Every column set explicitly: a Python-side onupdate has no place in a CTE.
        values: dict[str, Any] = {"updated_at": runs.c.updated_at}
        if leased:
            values["lease_expires_at"] = func.now() + bindparam(_LEASE, type_=Interval())
        fence = (
            update(runs)
            .where(*_run_conditions(running, leased))
            .values(values)
            .returning(runs.c.cancel_requested)
            .cte("fence")
        )
        # Typed: PostgreSQL types a bare parameter in a select list as text.
        rows = select(
            *(sql_cast(bindparam(_VALUE + c.name, type_=c.type), c.type) for c in columns)
        )
        rows = rows.select_from(fence)
        pg = postgresql_insert(table).from_select(
            [c.name for c in columns], rows, include_defaults=False
        )
        pg = pg.on_conflict_do_update(
            index_elements=list(keys),
            set_={c.name: pg.excluded[c.name] for c in columns if c.name not in keys},
        )
        return pg.add_cte(fence).returning(select(fence.c.cancel_requested).scalar_subquery())
    if dialect != "sqlite":
        raise NotImplementedError(f"fenced writes on {dialect!r}")
    rows = select(*(bindparam(_VALUE + c.name, type_=c.type) for c in columns)).where(
        exists().where(*_run_conditions(running, leased))
    )
    lite = sqlite_insert(table).from_select([c.name for c in columns], rows, include_defaults=False)
    return lite.on_conflict_do_update(
        index_elements=list(keys),
        set_={c.name: lite.excluded[c.name] for c in columns if c.name not in keys},
    )


@cache
def _bound_names(names: tuple[str, ...]) -> tuple[str, ...]:
    return tuple(_VALUE + name for name in names)


def fenced_upsert(
    connection: Connection,
    model: type[Base],
    values: Mapping[str, Any],
    keys: tuple[str, ...],
    guard: WriteGuard,
) -> Written:
    """INSERT ... ON CONFLICT (keys) DO UPDATE of one row, only while `guard` holds."""
    dialect = connection.dialect.name
    stmt = _statement(dialect, model, tuple(values), keys, guard.shape)
    params = dict(zip(_bound_names(tuple(values)), values.values(), strict=True))
    result = connection.execute(stmt, {**params, **guard.params()})
    if dialect == "sqlite":
        return Written(ok=result.rowcount == 1)
    row = result.first()
    return Written(ok=row is not None, cancel_requested=bool(row is not None and row[0]))


def why_refused(connection: Connection, guard: WriteGuard) -> str:
    """Which fence a refused write met: 'lease' (another process holds the run) or
    'status' (the run is no longer running: superseded, or ended elsewhere)."""
    runs = cast(Table, Run.__table__).c
    row = connection.execute(
        select(runs.status, runs.lease_owner).where(runs.id == guard.run_id)
    ).first()
    if guard.lease_owner is not None and (row is None or row.lease_owner != guard.lease_owner):
        return "lease"
    return "status"
