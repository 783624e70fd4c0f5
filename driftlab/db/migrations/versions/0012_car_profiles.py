"""Car profiles: a car's calibrated MPC weights (``driftlab calibrate``), versioned; a job records the profile its
weights came from.

Revision ID: 0012
Revises: 0011
"""

import sqlalchemy as sa
from alembic import op

revision = "0012"
down_revision = "0011"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "car_profiles",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("plant_model", sa.String(100), nullable=False, index=True),
        sa.Column("vehicle_id", sa.Integer, nullable=False),
        sa.Column("document", sa.JSON, nullable=False),
        sa.Column("created_at", sa.DateTime, nullable=False),
        sqlite_autoincrement=True,
    )
    with op.batch_alter_table("jobs") as batch:
        batch.add_column(sa.Column("profile_id", sa.Integer, nullable=True))
    op.execute("UPDATE meta SET value = '12' WHERE key = 'schema_version'")
