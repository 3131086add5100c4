"""times (docs/schedules.md#what-a-decision-records): a decision's place in time on a timed run

Revision ID: 0011_times
Revises: 0010_sites
Create Date: 2026-12-02 20:30:00.000000

All nullable: decisions of untimed runs (and every decision stored before this revision)
have none, and their chain links do not cover them (app.store.chain.TIME_FIELDS).
`start`/`end` are minutes from the plan's start; `seq` is the decision's place in the
order the graph decided (a timed run's decisions are chained in that order).
"""

from alembic import op
import sqlalchemy as sa


revision = "0011_times"
down_revision = "0010_sites"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("decisions", schema=None) as batch_op:
        batch_op.add_column(sa.Column("start", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("end", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("zone", sa.String(length=200), nullable=True))
        batch_op.add_column(sa.Column("travel", sa.Float(), nullable=True))
        batch_op.add_column(sa.Column("seq", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("later_by", sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("decisions", schema=None) as batch_op:
        for name in ("later_by", "seq", "travel", "zone", "end", "start"):
            batch_op.drop_column(name)
