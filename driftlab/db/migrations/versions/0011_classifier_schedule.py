"""The failure classifier's schedule: jobs stored before this revision conditioned it on every ask.

Revision 11 adds TuningSpec.classifier_every (5 for new jobs: from 40 evaluations on, the optimizer's failure
classifier is conditioned again every 5 tells). A stored job's or seeds study's spec without the key is pinned
to 1 here, so that resuming it asks what it would have asked.

Revision ID: 0011
Revises: 0010
"""

import json

import sqlalchemy as sa
from alembic import op

revision = "0011"
down_revision = "0010"
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
                spec = {**spec, "spec": {"classifier_every": 1, **spec["spec"]}}
            elif table == "jobs":
                spec = {"classifier_every": 1, **spec}
            else:
                continue  # a robustness study scores a given theta: nothing to pin
            bind.execute(sa.text(f"UPDATE {table} SET spec = :spec WHERE id = :id"),
                         {"spec": json.dumps(spec), "id": row_id})
    op.execute("UPDATE meta SET value = '11' WHERE key = 'schema_version'")
