"""widen decisions.task_id and decisions.robot_name to the API's 200-character names

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-23 03:00:00.000000
"""
from alembic import op
import sqlalchemy as sa


revision = '0004'
down_revision = '0003'
branch_labels = None
depends_on = None


def upgrade() -> None:
    # The API accepts names and task ids of up to 200 characters; PostgreSQL refused to
    # store a decision whose robot name or task id was longer than 128 (SQLite ignores it).
    with op.batch_alter_table('decisions', schema=None) as batch_op:
        batch_op.alter_column('task_id', existing_type=sa.String(length=128),
                              type_=sa.String(length=200), existing_nullable=False)
        batch_op.alter_column('robot_name', existing_type=sa.String(length=128),
                              type_=sa.String(length=200), existing_nullable=False)


def downgrade() -> None:
    with op.batch_alter_table('decisions', schema=None) as batch_op:
        batch_op.alter_column('robot_name', existing_type=sa.String(length=200),
                              type_=sa.String(length=128), existing_nullable=False)
        batch_op.alter_column('task_id', existing_type=sa.String(length=200),
                              type_=sa.String(length=128), existing_nullable=False)
