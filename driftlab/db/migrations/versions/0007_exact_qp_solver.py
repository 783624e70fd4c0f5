"""The exact QP solver: jobs and studies stored before this revision solved the constrained MPC steps with OSQP.

Revision 7 adds mpc.qp_solver, "daqp" (an exact active-set solve) by default for new jobs. A stored job's or
robustness study's config holds every key of its time, so a missing key means it ran OSQP: it is pinned to
"osqp" here, which reproduces its stored episodes bit for bit, so that resuming or rescoring it keeps its
objective.

Revision ID: 0007
Revises: 0006
"""

import json

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def _loads(value):
    return json.loads(value) if isinstance(value, str) else value


def _pinned(spec: dict) -> dict:
    config = {section: dict(values) for section, values in (spec.get("config") or {}).items()}
    config["mpc"] = {"qp_solver": "osqp", **config.get("mpc", {})}
    return {**spec, "config": config}


def upgrade() -> None:
    bind = op.get_bind()
    for table in ("jobs", "studies"):
        for row_id, raw in bind.execute(sa.text(f"SELECT id, spec FROM {table}")).all():
            spec = _loads(raw)
            if isinstance(spec.get("spec"), dict):  # a seeds study: the job spec it made its jobs from
                spec = {**spec, "spec": _pinned(spec["spec"])}
            elif table == "jobs" or isinstance(spec.get("config"), dict):
                spec = _pinned(spec)
            bind.execute(sa.text(f"UPDATE {table} SET spec = :spec WHERE id = :id"),
                         {"spec": json.dumps(spec), "id": row_id})
    op.execute("UPDATE meta SET value = '7' WHERE key = 'schema_version'")
