"""Notes on a job: free text a researcher keeps beside it (the dashboard's notes box, PATCH /api/jobs/{id}).

Revision ID: 0009
Revises: 0008
"""

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("jobs") as batch:
        batch.add_column(sa.Column("notes", sa.Text, nullable=False, server_default=""))
    op.execute("UPDATE meta SET value = '9' WHERE key = 'schema_version'")

