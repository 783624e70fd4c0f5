"""Validity as an outcome: CommonRoad's MB may lift a wheel off the road, and an episode outside its plant's model
ends as invalid.

Revision 16 adds plant.wheel_liftoff (on in MB's preset) and failure.invalid_ends_episode (on by default). A config
document stored before it, of a plant other than DriftLab's own or CommonRoad's STD (MB, or a car registered on
it), is pinned to the published model without the rule, as it ran: its jobs, studies and rescores re-run bit for
bit, and a car profile calibrated on the published model is taken only by jobs on it.

Revision ID: 0016
Revises: 0015
"""

import json

import sqlalchemy as sa
from alembic import op

revision = "0016"
down_revision = "0015"
branch_labels = None
depends_on = None

# Plants with no wheel loads: nothing to pin (their documents stay as stored, equal to new ones of the same settings).
_NO_WHEEL_LOADS = ("driftlab", "commonroad_std", "commonroad_std_reference")


def _loads(value):
    return json.loads(value) if isinstance(value, str) else value


def _pinned(config):
    """A stored config document (nested sections) as it ran, or None if it needs nothing."""
    if not isinstance(config, dict) or not isinstance(config.get("plant"), dict):
        return None
    plant = config["plant"]
    if plant.get("model", "driftlab") in _NO_WHEEL_LOADS or "wheel_liftoff" in plant:
        return None
    failure = config.get("failure") if isinstance(config.get("failure"), dict) else {}
    return {**config, "plant": {**plant, "wheel_liftoff": False},
            "failure": {**failure, "invalid_ends_episode": False}}


def _pinned_spec(spec):
    if not isinstance(spec, dict):
        return None
    if isinstance(spec.get("spec"), dict):  # a seeds study: the job spec it made its jobs from
        config = _pinned(spec["spec"].get("config"))
        return None if config is None else {**spec, "spec": {**spec["spec"], "config": config}}
    config = _pinned(spec.get("config"))
    return None if config is None else {**spec, "config": config}


def _profile(document):
    plant = document.get("plant") if isinstance(document, dict) else None
    if not isinstance(plant, dict) or plant.get("model", document.get("plant_model")) in _NO_WHEEL_LOADS \
            or document.get("plant_model") in _NO_WHEEL_LOADS or "wheel_liftoff" in plant:
        return None
    return {**document, "plant": {**plant, "wheel_liftoff": False}}


def _rewrite(bind, table, column, change):
    for row_id, raw in bind.execute(sa.text(f"SELECT id, {column} FROM {table}")).all():
        updated = change(_loads(raw))
        if updated is not None:
            bind.execute(sa.text(f"UPDATE {table} SET {column} = :value WHERE id = :id"),
                         {"value": json.dumps(updated), "id": row_id})


def upgrade() -> None:
    bind = op.get_bind()
    _rewrite(bind, "jobs", "spec", _pinned_spec)
    _rewrite(bind, "studies", "spec", _pinned_spec)
    _rewrite(bind, "rescores", "config", _pinned)
    _rewrite(bind, "car_profiles", "document", _profile)
    op.execute("UPDATE meta SET value = '16' WHERE key = 'schema_version'")
