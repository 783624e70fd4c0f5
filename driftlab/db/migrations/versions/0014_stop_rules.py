"""A job's stop rules (driftlab.core.stopping): the time it has run in all, and why a rule finished it.

Revision ID: 0014
Revises: 0013
"""

import sqlalchemy as sa
from alembic import op

revision = "0014"
down_revision = "0013"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("jobs") as batch:
        batch.add_column(sa.Column("run_s", sa.Float, nullable=False, server_default="0"))
        batch.add_column(sa.Column("stop_reason", sa.String(500), nullable=True))
    op.execute("UPDATE meta SET value = '14' WHERE key = 'schema_version'")
