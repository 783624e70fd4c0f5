"""A config resolved against the plant catalog: the presets, dotted overrides as the CLI, the REST API and storage
give them, and the fit of the controller's model to its car. The schema itself (:mod:`driftlab.core.config`) is
plain data; what a plant can take and what its car's model is are its catalog entry's (driftlab.core.plants), checked
here, where a config is parsed, once.
"""

from __future__ import annotations

from dataclasses import fields, replace
from typing import Any

from driftlab.core.config import (
    MODEL_FIT,
    START_FIT,
    EpisodeConfig,
    ScenarioConfig,
    dotted_config,
)
from driftlab.core.errors import ConfigError, OutsideDriftWindowError
from driftlab.core.mpc_config import MpcConfig
from driftlab.core.plant import PlantConfig
from driftlab.core.plants import check_plant, entry_of, installed_names, plant_type, preset_types
from driftlab.core.vehicle import VehicleParams


def preset_config(plant: str = "default", controller: str = "default") -> EpisodeConfig:
    """The episode config of a preset, by name. plant: "default" (mismatched), "nominal" (equals the controller's
    model), "commonroad_std" (CommonRoad's STD, vehicle 2, with the controller's model of that car), "commonroad_mb",
    or a plant installed under the entry-point group ``driftlab.plants`` (its own preset);
    controller: "default" (DriftLab's extended MPC) or "paper" (the paper's formulation)."""
    plant_config = _plant_preset(plant)
    check_plant(plant_config)
    controllers = {"default": entry_of(plant_config).controller, "paper": MpcConfig.paper}
    if controller not in controllers:
        raise ConfigError(f"controller must be 'default' or 'paper', got {controller!r}")
    sideslip_rad = entry_of(plant_config).default_sideslip_rad
    scenario = ScenarioConfig() if sideslip_rad is None else ScenarioConfig(sideslip_rad=sideslip_rad)
    return _fitted_unless_costly(EpisodeConfig(plant=plant_config, scenario=scenario, mpc=controllers[controller](),
                                               to_fit=frozenset((MODEL_FIT, START_FIT))))


def _plant_presets() -> dict[str, Any]:
    """``--plant`` presets: DriftLab's plant as it is ("default") and equal to its model ("nominal"), then each
    catalog entry that has one (driftlab.core.plants)."""
    return {"default": PlantConfig, "nominal": PlantConfig.nominal,
            **{name: entry.preset for name, entry in preset_types().items() if name != "default"}}


PLANT_PRESETS = _plant_presets()


def _plant_preset(name: str) -> PlantConfig:
    if name in PLANT_PRESETS:
        return PLANT_PRESETS[name]()
    entry = plant_type(name) if name in installed_names() else None
    if entry is None:
        raise ConfigError(f"plant must be one of {', '.join((*PLANT_PRESETS, *installed_names()))}, got {name!r}")
    return entry.preset()


def fitted(config: EpisodeConfig) -> EpisodeConfig:
    """``config`` with what is still to be fitted to its plant fitted (:attr:`EpisodeConfig.to_fit`): the
    controller's model (:func:`model_vehicle_for`), then the plant's start in the drift (:func:`started_in_drift`).
    A CommonRoad car costs 0.3-0.8 s the first time in a process (cached after).

    Raises:
        OutsideDriftWindowError: the scenario's sideslip is outside the car's window (naming it).
        ConfigError: inside it, the model cannot be fitted.
    """
    if not config.to_fit:
        return config
    vehicle = model_vehicle_for(config.plant, config.scenario) if MODEL_FIT in config.to_fit else config.vehicle
    plant = started_in_drift(config.plant, config.scenario) if START_FIT in config.to_fit else config.plant
    return replace(config, vehicle=vehicle, plant=plant, to_fit=frozenset())


def _fitted_unless_costly(config: EpisodeConfig) -> EpisodeConfig:
    """A plant that fits no model to itself (DriftLab's: Table I, no physics) is fitted at once; a plant that does
    (PlantType.fits_model) waits for :func:`fitted`."""
    return config if entry_of(config.plant).fits_model else fitted(config)


def model_vehicle_for(plant: PlantConfig, scenario: ScenarioConfig) -> VehicleParams:
    """The controller's vehicle a plant comes with (its catalog entry's): the paper's Table I for DriftLab's
    plants; for a CommonRoad plant the car's own mass, geometry and tyre shape, placed at its drift at the
    scenario's (left) radius and sideslip (raises ConfigError naming scenario.sideslip_rad where the car has no
    countersteer drift)."""
    return entry_of(plant).model_vehicle(plant, scenario.left_radius_m, scenario.sideslip_rad)


def started_in_drift(plant: PlantConfig, scenario: ScenarioConfig) -> PlantConfig:
    """The plant's start settings for the scenario's drift (its catalog entry's; a CommonRoad STD car's rear wheel
    at the slip of its own drift at the scenario's left radius and sideslip)."""
    return entry_of(plant).started_in_drift(plant, scenario.left_radius_m, scenario.sideslip_rad)


def _coerce(section: str, name: str, current: Any, raw: Any) -> Any:
    key = f"{section}.{name}"
    if isinstance(current, bool):
        if isinstance(raw, bool):
            return raw
        if isinstance(raw, str) and raw.lower() in ("true", "1", "yes", "on", "false", "0", "no", "off"):
            return raw.lower() in ("true", "1", "yes", "on")
        raise ConfigError(f"{key} must be true or false, got {raw!r}")
    if isinstance(current, int):
        try:
            value = int(raw) if not isinstance(raw, bool) else None
        except (TypeError, ValueError):
            value = None
        if value is None or (isinstance(raw, float) and raw != value):
            raise ConfigError(f"{key} must be an integer, got {raw!r}")
        return value
    if isinstance(current, float):
        try:
            if isinstance(raw, bool):
                raise ValueError
            return float(raw)
        except (TypeError, ValueError):
            raise ConfigError(f"{key} must be a number, got {raw!r}") from None
    if not isinstance(raw, str):
        raise ConfigError(f"{key} must be a string, got {raw!r}")
    return raw


def apply_overrides(config: EpisodeConfig, overrides: dict[str, Any]) -> EpisodeConfig:
    """A copy of ``config`` with dotted keys set, e.g. {"plant.cg_height_m": 0.3}; validated.

    Raises:
        ConfigError: unknown key, wrong type or value out of range (the message names the key).
    """
    sections = {f.name: getattr(config, f.name) for f in fields(config)}
    changes: dict[str, dict[str, Any]] = {}
    for dotted, raw in overrides.items():
        section, _, name = dotted.partition(".")
        if section not in sections or not name:
            raise ConfigError(f"unknown config key {dotted!r}; keys look like "
                              f"'<section>.<field>' with section one of {', '.join(sections)}", field=dotted)
        valid = {f.name for f in fields(sections[section])}
        if name not in valid:
            raise ConfigError(f"unknown config key {dotted!r}; {section} has: {', '.join(sorted(valid))}",
                              field=dotted)
        current = getattr(sections[section], name)
        changes.setdefault(section, {})[name] = _coerce(section, name, current, raw)
    if MODEL_FIT in config.to_fit and "vehicle" in changes:
        config = fitted(config)  # the model's settings changed: a change to the model fitted to the car, as before
        sections = {f.name: getattr(config, f.name) for f in fields(config)}
    _switch_plant_model(sections, changes)
    updated = {s: replace(sections[s], **c) for s, c in changes.items()}
    if "plant" in updated:
        check_plant(updated["plant"])
    return _refit_model_vehicle(replace(config, **{**sections, **updated}), changes)


def overrides_inside_window(config: EpisodeConfig, overrides: dict[str, Any]) -> EpisodeConfig:
    """:func:`apply_overrides`, except that where the controller's model of the car cannot be fitted at the preset's
    sideslip and no ``scenario.sideslip_rad`` is given (the VW Vanagon countersteers only from 0.57 rad at 44 m), the
    scenario's sideslip is the middle of the car's window: for what scans or searches the window (`driftlab
    equilibrium --window`, `driftlab calibrate`), not for a job, which is refused naming the window."""
    try:
        return fitted(apply_overrides(config, overrides))
    except OutsideDriftWindowError as exc:
        if exc.window is None or "scenario.sideslip_rad" in overrides:
            raise
        middle_rad = round((exc.window[0] + exc.window[1]) / 2, 2)
        return fitted(apply_overrides(config, {**overrides, "scenario.sideslip_rad": middle_rad}))


def _switch_plant_model(sections: dict[str, Any], changes: dict[str, dict[str, Any]]) -> None:
    """Setting ``plant.model`` (or ``plant.commonroad_vehicle``) to another car starts from that car's preset: the
    plant keys given apply on top. The plant's car needs no other keys either way."""
    plant_changes = changes.get("plant", {})
    current = sections["plant"]
    model = plant_changes.get("model", current.model)
    vehicle_id = plant_changes.get("commonroad_vehicle", current.commonroad_vehicle)
    if model == current.model and (not entry_of(current).own_car or vehicle_id == current.commonroad_vehicle):
        return
    entry = plant_type(model)
    if entry is not None and isinstance(vehicle_id, int) and not isinstance(vehicle_id, bool):
        sections["plant"] = entry.preset(vehicle_id)


def _refit_model_vehicle(config: EpisodeConfig, changes: dict[str, dict[str, Any]]) -> EpisodeConfig:
    """The controller follows the plant's car: switching back to DriftLab's plant restores Table I and the default
    weights, switching to a CommonRoad car takes its weights (driftlab.core.commonroad.weights; unless ``mpc.*``
    keys are given), and a CommonRoad plant's model is to be fitted to the car's drift at the scenario's radius and
    sideslip whenever the plant or the scenario changes (driftlab.core.commonroad.model_fit; :func:`fitted`),
    unless ``vehicle.*`` keys are given; the plant then starts in the car's drift (:func:`started_in_drift`)
    unless ``plant.initial_rear_slip`` is given."""
    plant_changes = changes.get("plant", {})
    plant_switched = "model" in plant_changes or "commonroad_vehicle" in plant_changes
    if plant_switched and "mpc" not in changes:  # and the default controller's weights for that car
        config = replace(config, mpc=entry_of(config.plant).controller())
    to_fit = set(config.to_fit) - ({MODEL_FIT} if "vehicle" in changes else set())
    refit = ("vehicle" not in changes and bool({"plant", "scenario"} & set(changes))
             and (entry_of(config.plant).own_car or plant_switched))
    if refit:
        to_fit |= {MODEL_FIT, START_FIT}
    if "initial_rear_slip" in plant_changes:
        to_fit.discard(START_FIT)
    return _fitted_unless_costly(replace(config, to_fit=frozenset(to_fit)))


def config_from_document(document: Any) -> EpisodeConfig:
    """The episode config a stored or posted document describes (see :func:`dotted_config`); validated."""
    return apply_overrides(EpisodeConfig(), dotted_config(document or {}))


def config_from_dict(data: dict[str, dict[str, Any]], base: EpisodeConfig | None = None) -> EpisodeConfig:
    """Inverse of :func:`config_to_dict`; missing keys keep ``base``'s values."""
    flat = {}
    for section, values in data.items():
        if not isinstance(values, dict):
            raise ConfigError(f"config.{section} must be an object of field values")
        flat.update({f"{section}.{k}": v for k, v in values.items()})
    return apply_overrides(base or EpisodeConfig(), flat)
