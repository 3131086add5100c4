"""fleet bridge (docs/fleet.md#one-bridge-per-database): the one active bridge's lease, its MQTT
client id and when the store's fleet began

Revision ID: 0016_fleet_bridge
Revises: 0015_fleet
Create Date: 2026-12-08 02:00:00.000000

A new table only; its one row is written by the first bridge that starts on the store.
"""

from alembic import op
import sqlalchemy as sa


revision = "0016_fleet_bridge"
down_revision = "0015_fleet"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "fleet_bridge",
        sa.Column("name", sa.String(length=32), nullable=False),
        sa.Column("holder", sa.String(length=128), nullable=True),
        sa.Column("expires_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("term", sa.Integer(), nullable=False),
        sa.Column("client_id", sa.String(length=64), nullable=False),
        sa.Column("since", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("name"),
    )


def downgrade() -> None:
    op.drop_table("fleet_bridge")
