"""Model correction: jobs stored before this revision learned theta's four parameters only.

Revision 8 adds theta.model_mu_scale and theta.model_c_scale (the controller model's friction and tyre-C
scales) and TuningSpec.model_correction, on by default for new jobs: their bounds join the job's search box. A
stored job's or seeds study's spec without the key is pinned to false here, so that resuming it asks in the
box it was learned in and its stored evaluations (whose theta means the model as configured, scales 1) keep
their objective.

Revision ID: 0008
Revises: 0007
"""

import json

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
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
                spec = {**spec, "spec": {"model_correction": False, **spec["spec"]}}
            elif table == "jobs":
                spec = {"model_correction": False, **spec}
            else:
                continue  # a robustness study scores a given theta: nothing to pin
            bind.execute(sa.text(f"UPDATE {table} SET spec = :spec WHERE id = :id"),
                         {"spec": json.dumps(spec), "id": row_id})
    op.execute("UPDATE meta SET value = '8' WHERE key = 'schema_version'")
