"""Jobs as documents for people: what the dashboard's new-job form starts from (plant presets as ``config`` keys,
the default bounds and each plant's own, the limits) and how two or more jobs' settings differ (the compare mode's
config diff)."""

from __future__ import annotations

from functools import lru_cache
from typing import Any

from driftlab.core.config import EpisodeConfig, config_to_dict, dotted_config
from driftlab.core.configure import PLANT_PRESETS, preset_config
from driftlab.core.limits import JOB_LIMITS
from driftlab.core.plants import entry_of
from driftlab.core.tuning import DEFAULT_BOUNDS, MODEL_BOUNDS, TuningSpec


@lru_cache(maxsize=1)
def plant_preset_sets() -> dict[str, dict[str, Any]]:
    """Each plant preset (``driftlab --plant``) as the dotted ``config`` keys that turn the default into it."""
    default = dotted_config(config_to_dict(EpisodeConfig()))
    out: dict[str, dict[str, Any]] = {}
    for name, make in PLANT_PRESETS.items():
        entry = entry_of(make())
        if entry.own_car:
            # Switching plant.model loads that car's preset and fits the controller's model to it
            # (driftlab.core.config), at the sideslip preset_config drifts it at.
            out[name] = {"plant.model": name, "scenario.sideslip_rad": entry.default_sideslip_rad}
            continue
        preset = dotted_config(config_to_dict(preset_config(name)))
        out[name] = {k: v for k, v in preset.items() if default.get(k) != v}
    return out


def plant_bounds() -> dict[str, dict[str, list[float]]]:
    """Per plant preset, where its jobs' default search box differs from DEFAULT_BOUNDS
    (driftlab.core.plants.PlantType.theta_bounds)."""
    return {name: {k: list(v) for k, v in entry_of(make()).theta_bounds.items()}
            for name, make in PLANT_PRESETS.items() if entry_of(make()).theta_bounds}


def job_form() -> dict[str, Any]:
    """What a new-job form needs: presets, the default config (dotted), bounds and limits."""
    return {"plant_presets": plant_preset_sets(), "default_config": dotted_config(config_to_dict(EpisodeConfig())),
            "default_bounds": {k: list(v) for k, v in DEFAULT_BOUNDS.items()}, "plant_bounds": plant_bounds(),
            "model_bounds": {k: list(v) for k, v in MODEL_BOUNDS.items()},
            "limits": {k: list(v) for k, v in JOB_LIMITS.items()}, "defaults": TuningSpec().to_dict() | {"config": {}}}


def flat_spec(spec: dict[str, Any]) -> dict[str, Any]:
    """A stored job spec as flat keys: its settings, ``bounds.<name>`` and ``config.<section>.<key>``."""
    out = {k: v for k, v in spec.items() if k not in ("bounds", "config")}
    out.update({f"bounds.{k}": list(v) for k, v in (spec.get("bounds") or {}).items()})
    out.update({f"config.{k}": v for k, v in dotted_config(spec.get("config") or {}).items()})
    return out


def spec_diff(specs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The keys whose values differ between the specs (a key one of them lacks is null there), sorted."""
    flats = [flat_spec(s) for s in specs]
    keys = sorted(set().union(*flats)) if flats else []
    return [{"key": k, "values": [f.get(k) for f in flats]} for k in keys
            if len({repr(f.get(k)) for f in flats}) > 1]
