"""unmeasured: why a site report's started -> done pair gives no duration

Revision ID: 0012_unmeasured
Revises: 0011_times
Create Date: 2026-12-03 13:30:00.000000

Nullable: a row with a duration, or without a `started` report, has no reason to give; the
rows stored before this revision keep the durations they were written with. The estimates
index gains the column, so the left-out pairs are counted in the same index-only scan
(docs/estimates.md, "Durations only from times the site gave").
"""

import sqlalchemy as sa
from alembic import op

revision = "0012_unmeasured"
down_revision = "0011_times"
branch_labels = None
depends_on = None

_OLD = [
    "site",
    "robot",
    "feature_set",
    "task_type",
    "predicted_bin",
    "success",
    "received_at",
    "log_minutes",
    "planned_minutes",
    "predicted",
]


def upgrade() -> None:
    with op.batch_alter_table("site_reports", schema=None) as batch_op:
        batch_op.add_column(sa.Column("unmeasured", sa.String(length=40), nullable=True))
    op.drop_index("ix_site_reports_estimates", table_name="site_reports")
    # After `success`: the estimates group on it, and a group that is a prefix of the index
    # is read in index order with no sort.
    grouped = _OLD[: _OLD.index("success") + 1]
    new = [*grouped, "unmeasured", *_OLD[len(grouped) :]]
    op.create_index("ix_site_reports_estimates", "site_reports", new)


def downgrade() -> None:
    op.drop_index("ix_site_reports_estimates", table_name="site_reports")
    op.create_index("ix_site_reports_estimates", "site_reports", _OLD)
    with op.batch_alter_table("site_reports", schema=None) as batch_op:
        batch_op.drop_column("unmeasured")
