"""console_sessions: signed-in supervisor console sessions

Revision ID: 0009
Revises: 0006_revisions
Create Date: 2026-12-01 21:00:00.000000
"""
from alembic import op
import sqlalchemy as sa


revision = '0009'
down_revision = '0006_revisions'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        'console_sessions',
        sa.Column('token_digest', sa.String(length=64), nullable=False),
        sa.Column('key_fingerprint', sa.String(length=64), nullable=True),
        sa.Column('csrf_token', sa.String(length=64), nullable=False),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.Column('expires_at', sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint('token_digest'),
    )
    with op.batch_alter_table('console_sessions', schema=None) as batch_op:
        batch_op.create_index('ix_console_sessions_key_fingerprint', ['key_fingerprint'])
        batch_op.create_index('ix_console_sessions_expires_at', ['expires_at'])


def downgrade() -> None:
    with op.batch_alter_table('console_sessions', schema=None) as batch_op:
        batch_op.drop_index('ix_console_sessions_expires_at')
        batch_op.drop_index('ix_console_sessions_key_fingerprint')
    op.drop_table('console_sessions')
