"""The job lease: which runner holds a job and when it last said so (driftlab.db.lifecycle).

Revision ID: 0003
Revises: 0002
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("jobs") as batch:
        batch.add_column(sa.Column("runner_id", sa.String(100)))
        batch.add_column(sa.Column("heartbeat_at", sa.DateTime))
    op.execute("UPDATE meta SET value = '3' WHERE key = 'schema_version'")
