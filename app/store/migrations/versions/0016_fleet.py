"""fleet (docs/fleet.md): the robots heard from, the orders sent, the outbox, headerIds per topic

Revision ID: 0015_fleet
Revises: 0014_site_report_members
Create Date: 2026-12-05 22:00:00.000000

New tables only: a store upgraded to this revision serves as before while no broker is
configured (LTAA_MQTT_URL unset).
"""

from alembic import op
import sqlalchemy as sa


revision = "0015_fleet"
down_revision = "0014_site_report_members"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "fleet_robots",
        sa.Column("manufacturer", sa.String(length=200), nullable=False),
        sa.Column("serial_number", sa.String(length=200), nullable=False),
        sa.Column("connection", sa.String(length=32), nullable=False),
        sa.Column("battery_charge", sa.Float(), nullable=True),
        sa.Column("charging", sa.Boolean(), nullable=True),
        sa.Column("fatal", sa.String(length=200), nullable=True),
        sa.Column("state_header_id", sa.Integer(), nullable=True),
        sa.Column("state_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("connection_header_id", sa.Integer(), nullable=True),
        sa.Column("connection_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("updated_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("manufacturer", "serial_number"),
    )
    op.create_table(
        "fleet_orders",
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("order_id", sa.String(length=700), nullable=False),
        sa.Column("lineage", sa.String(length=32), nullable=False),
        sa.Column("run_id", sa.String(length=32), nullable=False),
        sa.Column("task_index", sa.Integer(), nullable=False),
        sa.Column("task_id", sa.String(length=200), nullable=False),
        sa.Column("robot", sa.String(length=200), nullable=False),
        sa.Column("manufacturer", sa.String(length=200), nullable=False),
        sa.Column("serial_number", sa.String(length=200), nullable=False),
        sa.Column("update_id", sa.Integer(), nullable=False),
        sa.Column("planned_start", sa.Float(), nullable=True),
        sa.Column("planned_end", sa.Float(), nullable=True),
        sa.Column("state", sa.String(length=16), nullable=False),
        sa.Column("action_status", sa.String(length=16), nullable=True),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("updated_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("order_id"),
        sa.UniqueConstraint("lineage", "task_id", "robot", name="uq_fleet_orders_lineage_task_robot"),
    )
    op.create_index("ix_fleet_orders_lineage", "fleet_orders", ["lineage"], unique=False)
    op.create_index(
        "ix_fleet_orders_robot_state",
        "fleet_orders",
        ["manufacturer", "serial_number", "state"],
        unique=False,
    )
    op.create_table(
        "fleet_outbox",
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("topic", sa.String(length=1000), nullable=False),
        sa.Column("header_id", sa.Integer(), nullable=False),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("published_at", sa.DateTime(timezone=True), nullable=True),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("topic", "header_id", name="uq_fleet_outbox_topic_header"),
    )
    op.create_index("ix_fleet_outbox_published_at", "fleet_outbox", ["published_at"], unique=False)
    op.create_table(
        "fleet_headers",
        sa.Column("topic", sa.String(length=1000), nullable=False),
        sa.Column("last", sa.Integer(), nullable=False),
        sa.PrimaryKeyConstraint("topic"),
    )


def downgrade() -> None:
    op.drop_table("fleet_headers")
    op.drop_index("ix_fleet_outbox_published_at", table_name="fleet_outbox")
    op.drop_table("fleet_outbox")
    op.drop_index("ix_fleet_orders_robot_state", table_name="fleet_orders")
    op.drop_index("ix_fleet_orders_lineage", table_name="fleet_orders")
    op.drop_table("fleet_orders")
    op.drop_table("fleet_robots")
