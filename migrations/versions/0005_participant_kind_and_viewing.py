"""Participant kinds (real, pilot, bot), the consent text version each participant saw, a participant's details
(comprehension-check attempts) and a response's details (viewport).

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-24
"""

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("participant") as batch:
        batch.add_column(sa.Column("kind", sa.String(8), nullable=False, server_default="real"))
        batch.add_column(sa.Column("consent_version", sa.String(64), nullable=False, server_default=""))
        batch.add_column(sa.Column("details", sa.JSON(), nullable=True))
    with op.batch_alter_table("response") as batch:
        batch.add_column(sa.Column("details", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("response") as batch:
        batch.drop_column("details")
    with op.batch_alter_table("participant") as batch:
        batch.drop_column("details")
        batch.drop_column("consent_version")
        batch.drop_column("kind")
