"""run_annotations: the append-only chain of records made about a run after it finished

Revision ID: 0007_reviews_annotations
Revises: 0005
Create Date: 2026-12-01 20:45:00.000000
"""
from alembic import op
import sqlalchemy as sa


revision = '0007_reviews_annotations'
down_revision = '0005'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('run_annotations',
    sa.Column('id', sa.Integer(), autoincrement=True, nullable=False),
    sa.Column('run_id', sa.String(length=32), nullable=False),
    sa.Column('seq', sa.Integer(), nullable=False),
    sa.Column('kind', sa.String(length=32), nullable=False),
    sa.Column('detail', sa.JSON(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('chain_hash', sa.String(length=64), nullable=True),
    sa.Column('idempotency_key', sa.String(length=255), nullable=True),
    sa.Column('request_digest', sa.String(length=64), nullable=True),
    sa.ForeignKeyConstraint(['run_id'], ['runs.id'], ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id'),
    sa.UniqueConstraint('run_id', 'seq', name='uq_run_annotations_run_seq')
    )
    with op.batch_alter_table('run_annotations', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_run_annotations_run_id'), ['run_id'], unique=False)
        batch_op.create_index(
            batch_op.f('ix_run_annotations_idempotency_key'), ['idempotency_key'], unique=True
        )


def downgrade() -> None:
    with op.batch_alter_table('run_annotations', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_run_annotations_idempotency_key'))
        batch_op.drop_index(batch_op.f('ix_run_annotations_run_id'))
    op.drop_table('run_annotations')
