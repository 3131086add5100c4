"""runs.graph_version (safe upgrades), runs.chain_scheme and run_signatures (signed heads),
archived_runs (tombstones of archived runs)

Revision ID: 0008_yearlong
Revises: 0009
Create Date: 2026-12-01 21:00:00.000000
"""
from alembic import op
import sqlalchemy as sa


revision = '0008_yearlong'
down_revision = '0009'
branch_labels = None
depends_on = None


def upgrade() -> None:
    # Nullable: runs from before these columns resume as they always did (graph_version)
    # and verify under the scheme they were written with, v1 (chain_scheme).
    with op.batch_alter_table('runs', schema=None) as batch_op:
        batch_op.add_column(sa.Column('graph_version', sa.String(length=64), nullable=True))
        batch_op.add_column(sa.Column('chain_scheme', sa.String(length=32), nullable=True))
    op.create_table(
        'run_signatures',
        sa.Column('id', sa.Integer(), autoincrement=True, nullable=False),
        sa.Column('run_id', sa.String(length=32), nullable=False),
        sa.Column('reason', sa.String(length=32), nullable=False),
        sa.Column('key_id', sa.String(length=32), nullable=False),
        sa.Column('payload', sa.JSON(), nullable=False),
        sa.Column('signature', sa.String(length=128), nullable=False),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(['run_id'], ['runs.id'], ondelete='CASCADE'),
        sa.PrimaryKeyConstraint('id'),
    )
    op.create_index('ix_run_signatures_run_id', 'run_signatures', ['run_id'])
    op.create_table(
        'archived_runs',
        sa.Column('id', sa.String(length=32), nullable=False),
        sa.Column('lineage_head', sa.String(length=32), nullable=False),
        sa.Column('archive_file', sa.String(length=255), nullable=False),
        sa.Column('heads', sa.JSON(), nullable=False),
        sa.Column('verified', sa.Boolean(), nullable=False),
        sa.Column('status', sa.String(length=16), nullable=False),
        sa.Column('archived_at', sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint('id'),
    )


def downgrade() -> None:
    op.drop_table('archived_runs')
    op.drop_index('ix_run_signatures_run_id', table_name='run_signatures')
    op.drop_table('run_signatures')
    with op.batch_alter_table('runs', schema=None) as batch_op:
        batch_op.drop_column('chain_scheme')
        batch_op.drop_column('graph_version')
