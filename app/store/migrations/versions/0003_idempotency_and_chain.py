"""idempotency keys on runs; hash-chain columns on decisions and run events

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-23 01:30:00.000000
"""
from alembic import op
import sqlalchemy as sa


revision = '0003'
down_revision = '0002'
branch_labels = None
depends_on = None


def upgrade() -> None:
    # All nullable: rows written before this revision have no key and no chain link;
    # the trace verifier reports them as unchained rather than as tampered.
    with op.batch_alter_table('runs', schema=None) as batch_op:
        batch_op.add_column(sa.Column('idempotency_key', sa.String(length=255), nullable=True))
        batch_op.add_column(sa.Column('request_digest', sa.String(length=64), nullable=True))
        batch_op.create_index('ix_runs_idempotency_key', ['idempotency_key'], unique=True)
    with op.batch_alter_table('decisions', schema=None) as batch_op:
        batch_op.add_column(sa.Column('chain_hash', sa.String(length=64), nullable=True))
    with op.batch_alter_table('run_events', schema=None) as batch_op:
        batch_op.add_column(sa.Column('chain_hash', sa.String(length=64), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('run_events', schema=None) as batch_op:
        batch_op.drop_column('chain_hash')
    with op.batch_alter_table('decisions', schema=None) as batch_op:
        batch_op.drop_column('chain_hash')
    with op.batch_alter_table('runs', schema=None) as batch_op:
        batch_op.drop_index('ix_runs_idempotency_key')
        batch_op.drop_column('request_digest')
        batch_op.drop_column('idempotency_key')
