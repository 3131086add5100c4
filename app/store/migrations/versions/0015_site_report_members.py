"""site report members (docs/estimates.md#teams-count-once-per-member): one row per member

Revision ID: 0014_site_report_members
Revises: 0013_decision_team
Create Date: 2026-12-03 19:00:00.000000

A team task reported done or failed counts one outcome for each member, on the feature it
covered: its rows share the run and task and differ by robot, so the unique key gains the
robot. Every row stored before this revision is one robot's, and stays valid.
"""

from alembic import op

revision = "0014_site_report_members"
down_revision = "0013_decision_team"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("site_reports", schema=None) as batch_op:
        batch_op.drop_constraint("uq_site_reports_run_task", type_="unique")
        batch_op.create_unique_constraint(
            "uq_site_reports_run_task_robot", ["run_id", "task_index", "robot"]
        )


def downgrade() -> None:
    with op.batch_alter_table("site_reports", schema=None) as batch_op:
        batch_op.drop_constraint("uq_site_reports_run_task_robot", type_="unique")
        batch_op.create_unique_constraint("uq_site_reports_run_task", ["run_id", "task_index"])
