"""Studies: a seeds study links its jobs (jobs.study_id); a robustness study stores its grid's cells.

Revision ID: 0006
Revises: 0005
"""

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "studies",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("name", sa.String(200), nullable=False, unique=True),
        sa.Column("kind", sa.String(20), nullable=False),
        sa.Column("spec", sa.JSON, nullable=False),
        sa.Column("status", sa.String(20), nullable=False),
        sa.Column("error", sa.String(2000)),
        sa.Column("runner_id", sa.String(100)),
        sa.Column("heartbeat_at", sa.DateTime),
        sa.Column("created_at", sa.DateTime, nullable=False),
        sa.Column("updated_at", sa.DateTime, nullable=False),
        sqlite_autoincrement=True,
    )
    op.create_table(
        "study_cells",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("study_id", sa.Integer, sa.ForeignKey("studies.id"), nullable=False),
        sa.Column("index", sa.Integer, nullable=False),
        sa.Column("settings", sa.JSON, nullable=False),
        sa.Column("status", sa.String(20), nullable=False),
        sa.Column("J", sa.Float),
        sa.Column("n_completed", sa.Integer),
        sa.Column("seeds", sa.JSON),
        sa.Column("wall_ms", sa.Float),
        sa.Column("completed_at", sa.DateTime),
        sa.UniqueConstraint("study_id", "index"),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_study_cells_study_id", "study_cells", ["study_id"])
    with op.batch_alter_table("jobs") as batch:
        batch.add_column(sa.Column("study_id", sa.Integer))
    op.create_index("ix_jobs_study_id", "jobs", ["study_id"])
    op.execute("UPDATE meta SET value = '6' WHERE key = 'schema_version'")
