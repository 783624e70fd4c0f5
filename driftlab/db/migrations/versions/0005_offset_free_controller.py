"""Offset-free controller settings: jobs stored before this revision ran the controller without them.

Revision 5 adds mpc.feedback_in_model, mpc.disturbance_start_gain, mpc.estimator_hold_s and
mpc.estimator_uses_actuators and mpc.estimator_model, on by default for new jobs. A stored job's spec holds every key of its time, so a
missing key means the job ran without that part: it is pinned off here (which reproduces the earlier code bit for
bit), so that resuming or rescoring the job keeps its objective. Its other settings, the old default weights
included, are stored explicitly and stay.

Revision ID: 0005
Revises: 0004
"""

import json

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None

AS_BEFORE = {"feedback_in_model": False, "disturbance_start_gain": 0.0, "estimator_hold_s": 0.0,
             "estimator_uses_actuators": False, "estimator_model": "nonlinear"}


def _loads(value):
    return json.loads(value) if isinstance(value, str) else value


def upgrade() -> None:
    bind = op.get_bind()
    for job_id, raw in bind.execute(sa.text("SELECT id, spec FROM jobs")).all():
        spec = _loads(raw)
        config = {section: dict(values) for section, values in (spec.get("config") or {}).items()}
        config["mpc"] = {**AS_BEFORE, **config.get("mpc", {})}
        spec = {**spec, "config": config}
        bind.execute(sa.text("UPDATE jobs SET spec = :spec WHERE id = :id"), {"spec": json.dumps(spec), "id": job_id})
    op.execute("UPDATE meta SET value = '5' WHERE key = 'schema_version'")
