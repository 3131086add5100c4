"""reviews.idempotency_key and reviews.request_digest: Idempotency-Key on resolutions

Revision ID: 0010_review_idempotency
Revises: 0009
Create Date: 2026-12-01 21:50:00.000000
"""
from alembic import op
import sqlalchemy as sa


revision = '0010_review_idempotency'
down_revision = '0009'
branch_labels = None
depends_on = None


def upgrade() -> None:
    # Nullable: resolutions stored before carry no key (a retry of them is a 409, as before).
    with op.batch_alter_table('reviews', schema=None) as batch_op:
        batch_op.add_column(sa.Column('idempotency_key', sa.String(length=255), nullable=True))
        batch_op.add_column(sa.Column('request_digest', sa.String(length=64), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('reviews', schema=None) as batch_op:
        batch_op.drop_column('request_digest')
        batch_op.drop_column('idempotency_key')
