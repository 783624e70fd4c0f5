"""Hand-picked thetas a job evaluates next (POST /api/jobs/{id}/enqueue), and which evaluations were such.

Revision ID: 0015
Revises: 0014
"""

import sqlalchemy as sa
from alembic import op

revision = "0015"
down_revision = "0014"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "enqueued_thetas",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("job_id", sa.Integer, sa.ForeignKey("jobs.id"), nullable=False, index=True),
        sa.Column("theta", sa.JSON, nullable=False),
        sa.Column("created_at", sa.DateTime, nullable=False),
        sqlite_autoincrement=True,
    )
    with op.batch_alter_table("evaluations") as batch:
        batch.add_column(sa.Column("enqueued", sa.Boolean, nullable=False, server_default=sa.false()))
    op.execute("UPDATE meta SET value = '15' WHERE key = 'schema_version'")
