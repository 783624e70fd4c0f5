"""The local phase: jobs stored before this revision filled the whole box with their seed points.

Revision 10 adds TuningSpec.local_phase, on by default for new jobs (with the model corrections, the seed points
start near the uncorrected model and the GP's proposals stay in a box that grows to the whole). A stored job's or
seeds study's spec without the key is pinned to false here, so that resuming it asks what it would have asked.

Revision ID: 0010
Revises: 0009
"""

import json

import sqlalchemy as sa
from alembic import op

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None


def _loads(value):
    return json.loads(value) if isinstance(value, str) else value


def upgrade() -> None:
    bind = op.get_bind()
    for table in ("jobs", "studies"):
        for row_id, raw in bind.execute(sa.text(f"SELECT id, spec FROM {table}")).all():
            spec = _loads(raw)
            if isinstance(spec.get("spec"), dict):  # a seeds study: the job spec it made its jobs from
                spec = {**spec, "spec": {"local_phase": False, **spec["spec"]}}
            elif table == "jobs":
                spec = {"local_phase": False, **spec}
            else:
                continue  # a robustness study scores a given theta: nothing to pin
            bind.execute(sa.text(f"UPDATE {table} SET spec = :spec WHERE id = :id"),
                         {"spec": json.dumps(spec), "id": row_id})
    op.execute("UPDATE meta SET value = '10' WHERE key = 'schema_version'")
