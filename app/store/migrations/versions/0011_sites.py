"""sites (docs/estimates.md#sites): runs.site, and site_reports, the outcome rows the estimates read

Revision ID: 0010_sites
Revises: 0008_yearlong
Create Date: 2026-12-10 09:00:00.000000

Reports sent before this revision have no outcome row: `ltaa rebuild-estimates` derives the
table from the execution-report events once (docs/estimates.md).
"""

from alembic import op
import sqlalchemy as sa


revision = "0010_sites"
down_revision = "0008_yearlong"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.add_column(
            sa.Column("site", sa.String(length=200), nullable=False, server_default="default")
        )
        batch_op.create_index("ix_runs_site", ["site"], unique=False)
    op.create_table(
        "site_reports",
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("site", sa.String(length=200), nullable=False),
        sa.Column("run_id", sa.String(length=32), nullable=False),
        sa.Column("task_index", sa.Integer(), nullable=False),
        sa.Column("task_id", sa.String(length=200), nullable=False),
        sa.Column("robot", sa.String(length=200), nullable=False),
        sa.Column("task_type", sa.String(length=200), nullable=False),
        sa.Column("features", sa.Text(), nullable=False),
        sa.Column("feature_set", sa.String(length=64), nullable=False),
        sa.Column("success", sa.Boolean(), nullable=False),
        sa.Column("predicted", sa.Float(), nullable=False),
        sa.Column("predicted_bin", sa.Integer(), nullable=False),
        sa.Column("reported_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("received_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("minutes", sa.Float(), nullable=True),
        sa.Column("log_minutes", sa.Float(), nullable=True),
        sa.Column("planned_minutes", sa.Float(), nullable=True),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("run_id", "task_index", name="uq_site_reports_run_task"),
    )
    op.create_index(
        "ix_site_reports_estimates",
        "site_reports",
        [
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
        ],
        unique=False,
    )


def downgrade() -> None:
    op.drop_index("ix_site_reports_estimates", table_name="site_reports")
    op.drop_table("site_reports")
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.drop_index("ix_runs_site")
        batch_op.drop_column("site")
