"""The site's outcomes (docs/estimates.md#counting-each-report-once): one row per task reported done
or failed (a team task: one per member), written in the same transaction as the report, so the
estimates of a site with 100,000 reports are one indexed aggregate rather than a walk over every
run's record.

The row is derived, never the record: `ltaa rebuild-estimates` recomputes the table from the
execution-report events and annotations (app.sites.rebuild), and a test proves both agree.
A report is counted on the run it was sent to; the copies a revision carries of its pinned
tasks' reports are no reports and write no row (the unique key would refuse a second row
for the same run, task and robot anyway).
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import (
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import Mapped, mapped_column

from app.domain.models import MAX_NAME_CHARS
from app.store.models import Base


class SiteReport(Base):
    __tablename__ = "site_reports"
    __table_args__ = (
        # One row per robot of a reported task: a team task has one per member
        # (docs/estimates.md#teams-count-once-per-member).
        UniqueConstraint("run_id", "task_index", "robot", name="uq_site_reports_run_task_robot"),
        # The estimates are one grouped scan of a site's rows up to a time: this index holds
        # every column the scan reads, in group order, so it never touches the table
        # (100,000 reports read in well under the 200 ms the issue asks for, on SQLite).
        Index(
            "ix_site_reports_estimates",
            "site",
            "robot",
            "feature_set",
            "task_type",
            "predicted_bin",
            "success",
            "unmeasured",  # grouped on too: before received_at, so the group is a prefix
            "received_at",
            "log_minutes",
            "planned_minutes",
            "predicted",
        ),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    site: Mapped[str] = mapped_column(String(MAX_NAME_CHARS))
    run_id: Mapped[str] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"))
    task_index: Mapped[int] = mapped_column(Integer)
    task_id: Mapped[str] = mapped_column(String(MAX_NAME_CHARS))
    robot: Mapped[str] = mapped_column(String(MAX_NAME_CHARS))
    task_type: Mapped[str] = mapped_column(String(MAX_NAME_CHARS))
    # The task's features as a JSON list, sorted (PostgreSQL's json type has no equality),
    # and its SHA-256: the index groups on the digest, since a task may name 100 features of
    # 200 characters and PostgreSQL refuses index entries over 2,704 bytes.
    features: Mapped[str] = mapped_column(Text)
    feature_set: Mapped[str] = mapped_column(String(64))
    success: Mapped[bool] = mapped_column(Boolean)
    # The success the plan expected of this task (its decision's S), for the reliability
    # plot; and its tenth (0..9), to group by without arithmetic that databases round apart.
    predicted: Mapped[float] = mapped_column(Float)
    predicted_bin: Mapped[int] = mapped_column(Integer)
    # When the site says it ended (the report's `at`), and when the server recorded it (the
    # report's event or annotation): `as_of` reads the latter.
    reported_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    received_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    # started -> done with both times: the observed minutes (and their log); the planned
    # minutes when the run's instance gave the task a duration (docs/schedules.md#the-model).
    minutes: Mapped[float | None] = mapped_column(Float, nullable=True)
    log_minutes: Mapped[float | None] = mapped_column(Float, nullable=True)
    planned_minutes: Mapped[float | None] = mapped_column(Float, nullable=True)
    # Why a started -> done pair gives no duration (app.store.site_repository.Unmeasured);
    # null when it gives one, or when no `started` was reported.
    unmeasured: Mapped[str | None] = mapped_column(String(40), nullable=True)
