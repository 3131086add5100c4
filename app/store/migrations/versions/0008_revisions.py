"""living plans: revision columns on runs, pins on decisions, execution reports

Revision ID: 0006_revisions
Revises: 0008_reviews
Create Date: 2026-12-01 21:00:00.000000

Also the merge point of the webhooks (0005) and reviews (0007_reviews_annotations)
migrations, which both follow 0004 (two heads would stop `alembic upgrade head`); re-chain
at merge if main orders them differently.
"""
from alembic import op
import sqlalchemy as sa


revision = '0006_revisions'
down_revision = '0008_reviews'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('runs', schema=None) as batch_op:
        batch_op.add_column(sa.Column('revision_of', sa.String(length=32), nullable=True))
        batch_op.add_column(
            sa.Column('revision', sa.Integer(), nullable=False, server_default='0')
        )
        batch_op.add_column(sa.Column('superseded_by', sa.String(length=32), nullable=True))
        batch_op.add_column(sa.Column('chain_anchor', sa.String(length=64), nullable=True))
        batch_op.create_index(batch_op.f('ix_runs_revision_of'), ['revision_of'], unique=False)
    with op.batch_alter_table('decisions', schema=None) as batch_op:
        batch_op.add_column(sa.Column('pinned', sa.Boolean(), nullable=True))
        batch_op.add_column(sa.Column('pinned_from', sa.String(length=64), nullable=True))
    op.create_table('execution_reports',
    sa.Column('id', sa.Integer(), autoincrement=True, nullable=False),
    sa.Column('run_id', sa.String(length=32), nullable=False),
    sa.Column('task_index', sa.Integer(), nullable=False),
    sa.Column('task_id', sa.String(length=200), nullable=False),
    sa.Column('state', sa.String(length=16), nullable=False),
    sa.Column('started_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('ended_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('updated_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['run_id'], ['runs.id'], ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id'),
    sa.UniqueConstraint('run_id', 'task_index', name='uq_execution_run_task')
    )
    with op.batch_alter_table('execution_reports', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_execution_reports_run_id'), ['run_id'], unique=False)
    op.create_table('request_keys',
    sa.Column('id', sa.Integer(), autoincrement=True, nullable=False),
    sa.Column('key', sa.String(length=255), nullable=False),
    sa.Column('request_digest', sa.String(length=64), nullable=False),
    sa.Column('run_id', sa.String(length=32), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['run_id'], ['runs.id'], ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id')
    )
    with op.batch_alter_table('request_keys', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_request_keys_key'), ['key'], unique=True)


def downgrade() -> None:
    with op.batch_alter_table('request_keys', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_request_keys_key'))
    op.drop_table('request_keys')
    with op.batch_alter_table('execution_reports', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_execution_reports_run_id'))
    op.drop_table('execution_reports')
    with op.batch_alter_table('decisions', schema=None) as batch_op:
        batch_op.drop_column('pinned_from')
        batch_op.drop_column('pinned')
    with op.batch_alter_table('runs', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_runs_revision_of'))
        batch_op.drop_column('chain_anchor')
        batch_op.drop_column('superseded_by')
        batch_op.drop_column('revision')
        batch_op.drop_column('revision_of')
