"""Durations of a screen in 64 bits: a screen left open for more than 24.8 days overflowed PostgreSQL's INTEGER
(SQLite's INTEGER was already 64-bit; its table is rebuilt with the new declared type, data kept).

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-24
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("response") as batch:
        batch.alter_column("server_ms", type_=sa.BigInteger(), existing_type=sa.Integer(), existing_nullable=False)
        batch.alter_column("client_ms", type_=sa.BigInteger(), existing_type=sa.Integer(), existing_nullable=True)


def downgrade() -> None:
    # Durations that do not fit 32 bits are capped at the largest INTEGER rather than refused.
    op.execute("UPDATE response SET server_ms = 2147483647 WHERE server_ms > 2147483647")
    op.execute("UPDATE response SET client_ms = 2147483647 WHERE client_ms > 2147483647")
    with op.batch_alter_table("response") as batch:
        batch.alter_column("server_ms", type_=sa.Integer(), existing_type=sa.BigInteger(), existing_nullable=False)
        batch.alter_column("client_ms", type_=sa.Integer(), existing_type=sa.BigInteger(), existing_nullable=True)
