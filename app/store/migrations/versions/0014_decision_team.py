"""decision team (docs/allocation.md#teams): a team decision's members

Revision ID: 0013_decision_team
Revises: 0012_unmeasured
Create Date: 2026-12-03 18:30:00.000000

Nullable: a single-robot decision (and every decision stored before this revision) has no
team, and its chain link does not cover the column (app.store.chain.TEAM_FIELDS), so every
earlier run still verifies.
"""

import sqlalchemy as sa
from alembic import op

revision = "0013_decision_team"
down_revision = "0012_unmeasured"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("decisions", schema=None) as batch_op:
        batch_op.add_column(sa.Column("team", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("decisions", schema=None) as batch_op:
        batch_op.drop_column("team")
