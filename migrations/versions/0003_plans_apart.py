"""Plans in their own table, off the participant row that every answer rewrites; the response index that the
unique (participant_id, step) constraint already provides is dropped.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-21
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "participant_plan",
        sa.Column("participant_id", sa.Integer(), nullable=False),
        sa.Column("plan", sa.JSON(), nullable=False),
        sa.ForeignKeyConstraint(
            ["participant_id"],
            ["participant.id"],
            ondelete="CASCADE",
            name="fk_participant_plan_participant_id_participant",
        ),
        sa.PrimaryKeyConstraint("participant_id", name="pk_participant_plan"),
    )
    op.execute(
        'INSERT INTO participant_plan (participant_id, "plan") SELECT id, "plan" FROM participant '
        """WHERE "plan" IS NOT NULL AND CAST("plan" AS TEXT) <> 'null'"""
    )
    with op.batch_alter_table("participant") as batch:
        batch.drop_column("plan")
    op.drop_index("ix_response_participant_id", table_name="response")


def downgrade() -> None:
    op.create_index("ix_response_participant_id", "response", ["participant_id"])
    with op.batch_alter_table("participant") as batch:
        batch.add_column(sa.Column("plan", sa.JSON(), nullable=True))
    op.execute(
        'UPDATE participant SET "plan" = (SELECT "plan" FROM participant_plan '
        "WHERE participant_plan.participant_id = participant.id)"
    )
    op.drop_table("participant_plan")
