"""Exclusion flag and note set by the admin; count of failed attention checks.

Revision ID: 0002
Revises: 0001
Create Date: 2024-06-02
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("participant") as batch:
        batch.add_column(sa.Column("excluded", sa.Boolean(), nullable=False, server_default=sa.false()))
        batch.add_column(sa.Column("exclusion_note", sa.Text(), nullable=False, server_default=""))
        batch.add_column(sa.Column("attention_failures", sa.Integer(), nullable=False, server_default="0"))


def downgrade() -> None:
    with op.batch_alter_table("participant") as batch:
        batch.drop_column("attention_failures")
        batch.drop_column("exclusion_note")
        batch.drop_column("excluded")
