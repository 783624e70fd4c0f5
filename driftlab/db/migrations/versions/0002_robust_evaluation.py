"""Robust evaluation: each evaluation's episodes (seeds) and the seed of its stored trajectory.

Jobs stored before this revision ran one deterministic episode per evaluation on a plant without per-episode
variation: their specs are pinned to that (variation keys 0, robust_samples 1, confirm_samples 0), so that
resuming one keeps its objective, and each evaluation gets seed 0, which reproduces it.

Revision ID: 0002
Revises: 0001
"""

import json

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None

VARIATION_OFF = {"friction_spread": 0.0, "mass_spread": 0.0, "steer_lag_spread_s": 0.0,
                 "initial_speed_spread_mps": 0.0, "initial_sideslip_spread_rad": 0.0,
                 "initial_yaw_rate_spread_radps": 0.0, "noise_speed_mps": 0.0, "noise_sideslip_rad": 0.0,
                 "noise_yaw_rate_radps": 0.0, "noise_position_m": 0.0, "noise_heading_rad": 0.0}


def _loads(value):
    return json.loads(value) if isinstance(value, str) else value


def upgrade() -> None:
    with op.batch_alter_table("evaluations") as batch:
        batch.add_column(sa.Column("seeds", sa.JSON))
        batch.add_column(sa.Column("trajectory_seed", sa.Integer))
    bind = op.get_bind()
    for job_id, raw in bind.execute(sa.text("SELECT id, spec FROM jobs")).all():
        spec = _loads(raw)
        config = {section: dict(values) for section, values in (spec.get("config") or {}).items()}
        config["plant"] = {**VARIATION_OFF, **config.get("plant", {})}
        spec = {**spec, "robust_samples": spec.get("robust_samples", 1),
                "confirm_samples": spec.get("confirm_samples", 0), "config": config}
        bind.execute(sa.text("UPDATE jobs SET spec = :spec WHERE id = :id"), {"spec": json.dumps(spec), "id": job_id})
    rows = bind.execute(sa.text("SELECT id, status, J, metrics FROM evaluations WHERE seeds IS NULL")).all()
    for evaluation_id, status, value, metrics in rows:
        fraction = float(_loads(metrics).get("completed_fraction", 0.0))
        seeds = [{"seed": 0, "status": status, "J": value, "completed_fraction": fraction}]
        bind.execute(sa.text("UPDATE evaluations SET seeds = :seeds, trajectory_seed = 0 WHERE id = :id"),
                     {"seeds": json.dumps(seeds), "id": evaluation_id})
    op.execute("UPDATE meta SET value = '2' WHERE key = 'schema_version'")
