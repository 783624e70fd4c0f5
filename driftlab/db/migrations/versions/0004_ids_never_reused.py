"""Ids are never reused: jobs and evaluations become AUTOINCREMENT tables (SQLite otherwise hands a deleted
job's id, the largest, to the next job, and old links would show a different job).

Revision ID: 0004
Revises: 0003
"""

from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    if op.get_bind().dialect.name != "sqlite":
        return  # other databases do not reuse sequence values
    for table in ("jobs", "evaluations"):
        with op.batch_alter_table(table, recreate="always", table_kwargs={"sqlite_autoincrement": True}):
            pass
    op.execute("UPDATE meta SET value = '4' WHERE key = 'schema_version'")
