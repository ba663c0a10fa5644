"""A participant's identity is the three ids of the platform's link (PROLIFIC_PID, STUDY_ID, SESSION_ID; MTurk's
workerId, hitId, assignmentId), not the platform id alone: someone who knows a participant's id but not their
session ids starts a record of their own instead of being refused, so the reply tells nothing and no one can
claim an id before its owner arrives.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-25
"""

from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("participant") as batch:
        batch.drop_constraint("uq_participant_identity", type_="unique")
        batch.create_unique_constraint(
            "uq_participant_identity", ["study", "platform", "external_id", "platform_study_id", "platform_session_id"]
        )


def downgrade() -> None:  # fails if an id has records with other study or session ids: remove those first
    with op.batch_alter_table("participant") as batch:
        batch.drop_constraint("uq_participant_identity", type_="unique")
        batch.create_unique_constraint("uq_participant_identity", ["study", "platform", "external_id"])
