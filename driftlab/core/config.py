"""The one configuration schema shared by the CLI, the REST API and storage.

An :class:`EpisodeConfig` groups frozen, validated sections. Every value is reachable by a dotted key
(``plant.friction_scale``, ``mpc.q_sideslip``, ``vehicle.mass_kg`` ...) through :func:`apply_overrides`,
and :func:`config_to_dict` / :func:`config_from_dict` round-trip it through plain JSON types.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, is_dataclass, replace
from typing import Any

from driftlab.core.errors import ConfigError, OutsideDriftWindowError
from driftlab.core.mpc import MpcConfig
from driftlab.core.plant import PlantConfig
from driftlab.core.theta import (  # noqa: F401  # re-exported: callers take theta from the config schema
    MODEL_SCALE_LIMITS,
    PAPER_THETA,
    THETA_KEYS,
    THETA_LIMITS,
    Theta,
)
from driftlab.core.track import MAX_LAPS
from driftlab.core.validation import check_ranges
from driftlab.core.vehicle import VehicleParams


@dataclass(frozen=True)
class ScenarioConfig:
    """The figure-8 scenario.

    Attributes:
        left_radius_m, right_radius_m: circle radii [m].
        sideslip_rad: |beta| of the sustained drifts [rad].
        lookahead_m: look-ahead distance x_la of the steering feedback [m].
        max_time_s: the episode stops here if not finished [s].
        settle_tolerance_rad: |beta - beta_ref| that ends an inertia phase [rad].
        speed_change_accel_mps2: where the circles' drift speeds differ, the reference speed of a sustained
            drift moves to the next circle's at this rate so as to reach it at the trigger point [m/s^2]
            (0: it steps at the flick, which the car cannot follow from a 44 m into a 25 m circle).
        laps: laps of the 8 in one episode: the paper's pattern repeated, J over the whole run; ``max_time_s``
            is per lap.
    """

    left_radius_m: float = 44.0
    right_radius_m: float = 44.0
    sideslip_rad: float = 0.4
    lookahead_m: float = 7.0
    max_time_s: float = 40.0
    settle_tolerance_rad: float = 0.05
    speed_change_accel_mps2: float = 5.5
    laps: int = 1

    def __post_init__(self) -> None:
        check_ranges(self, "scenario", {
            "left_radius_m": (5.0, 500.0), "right_radius_m": (5.0, 500.0), "sideslip_rad": (0.05, 1.0),
            "lookahead_m": (0.0, 50.0), "max_time_s": (1.0, 300.0), "settle_tolerance_rad": (0.001, 0.5),
            "speed_change_accel_mps2": (0.0, 20.0), "laps": (1, MAX_LAPS)})
        if not isinstance(self.laps, int):
            raise ConfigError(f"scenario.laps must be an integer in [1, {MAX_LAPS}], got {self.laps!r}")


@dataclass(frozen=True)
class FailureLimits:
    """When an episode is stopped as failed (docs/reference.md, The paper's controller: rules, none flagged a good run).

    Attributes:
        max_sideslip_rad: |beta| above this: spun out.
        max_yaw_rate_radps: |r| above this: spun out (flick peaks reach ~2 rad/s).
        max_lateral_error_m: |e| above this: left the track.
        min_speed_mps: V below this: stalled.
        gripup_sideslip_rad: |beta| below this or of the wrong sign counts as gripping up ...
        gripup_time_s: ... for longer than this ...
        gripup_grace_s: ... counted from this long after a trigger (the flick crosses beta = 0).
        max_invalid_s: time outside the plant's model (a plant that reports it: CommonRoad's MB, see
            PlantConfig.wheel_liftoff) after which the episode ends as invalid, its J a failure's: a result
            about a car its model does not describe is not a result about a car. A short tolerance, not zero: a
            wheel touches zero load for a sample now and then in a flick.
        invalid_ends_episode: the rule above applies (stored jobs of releases before it ran without it and keep
            their results).
    """

    max_sideslip_rad: float = 1.2
    max_yaw_rate_radps: float = 3.0
    max_lateral_error_m: float = 10.0
    min_speed_mps: float = 8.0
    gripup_sideslip_rad: float = 0.1
    gripup_time_s: float = 1.0
    gripup_grace_s: float = 2.5
    max_invalid_s: float = 0.2
    invalid_ends_episode: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.invalid_ends_episode, bool):
            raise ConfigError(f"failure.invalid_ends_episode must be true or false, got {self.invalid_ends_episode!r}")
        check_ranges(self, "failure", {
            "max_sideslip_rad": (0.2, 1.6), "max_yaw_rate_radps": (0.5, 10.0), "max_lateral_error_m": (0.5, 50.0),
            "min_speed_mps": (0.5, 30.0), "gripup_sideslip_rad": (0.0, 0.5), "gripup_time_s": (0.05, 10.0),
            "gripup_grace_s": (0.0, 10.0), "max_invalid_s": (0.0, 300.0)})


# What a plant that fits the controller's model to itself (PlantType.fits_model) fits when a config first runs:
# the controller's model at the scenario's drift, and the plant's start in that drift.
MODEL_FIT = "vehicle"
START_FIT = "plant.initial_rear_slip"


@dataclass(frozen=True)
class EpisodeConfig:
    """Everything an episode needs besides theta.

    Attributes:
        to_fit: what is still to be fitted to the plant before the config runs (:data:`MODEL_FIT`, :data:`START_FIT`;
            :func:`fitted`). Parsing does no physics: a CommonRoad car's model is fitted to its drift when the
            config first runs (a job's when a runner claims it, and stored with the job), and a config document
            leaves out what is still to be fitted (:func:`config_to_dict`).
    """

    vehicle: VehicleParams = field(default_factory=VehicleParams)
    plant: PlantConfig = field(default_factory=PlantConfig)
    mpc: MpcConfig = field(default_factory=MpcConfig)
    scenario: ScenarioConfig = field(default_factory=ScenarioConfig)
    failure: FailureLimits = field(default_factory=FailureLimits)
    to_fit: frozenset[str] = frozenset()

    @classmethod
    def preset(cls, plant: str = "default", controller: str = "default") -> EpisodeConfig:
        """Preset by name. plant: "default" (mismatched), "nominal" (equals the controller's model),
        "commonroad_std" (CommonRoad's STD, vehicle 2, with the controller's model of that car), "commonroad_mb",
        or a plant installed under the entry-point group ``driftlab.plants`` (its own preset);
        controller: "default" (DriftLab's extended MPC) or "paper" (the paper's formulation)."""
        plant_config = _plant_preset(plant)
        controllers = {"default": plant_config.plant_type.controller, "paper": MpcConfig.paper}
        if controller not in controllers:
            raise ConfigError(f"controller must be 'default' or 'paper', got {controller!r}")
        sideslip_rad = plant_config.plant_type.default_sideslip_rad
        scenario = ScenarioConfig() if sideslip_rad is None else ScenarioConfig(sideslip_rad=sideslip_rad)
        return _fitted_unless_costly(cls(plant=plant_config, scenario=scenario, mpc=controllers[controller](),
                                         to_fit=frozenset((MODEL_FIT, START_FIT))))


def _plant_presets() -> dict[str, Any]:
    """``--plant`` presets: DriftLab's plant as it is ("default") and equal to its model ("nominal"), then each
    catalog entry that has one (driftlab.core.plants)."""
    from driftlab.core.plants import preset_types

    return {"default": PlantConfig, "nominal": PlantConfig.nominal,
            **{name: entry.preset for name, entry in preset_types().items() if name != "default"}}


PLANT_PRESETS = _plant_presets()


def _plant_preset(name: str) -> PlantConfig:
    if name in PLANT_PRESETS:
        return PLANT_PRESETS[name]()
    from driftlab.core.plants import installed_names, plant_type

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
    return config if config.plant.plant_type.fits_model else fitted(config)


def model_vehicle_for(plant: PlantConfig, scenario: ScenarioConfig) -> VehicleParams:
    """The controller's vehicle a plant comes with (its catalog entry's): the paper's Table I for DriftLab's
    plants; for a CommonRoad plant the car's own mass, geometry and tyre shape, placed at its drift at the
    scenario's (left) radius and sideslip (raises ConfigError naming scenario.sideslip_rad where the car has no
    countersteer drift)."""
    return plant.plant_type.model_vehicle(plant, scenario.left_radius_m, scenario.sideslip_rad)


def started_in_drift(plant: PlantConfig, scenario: ScenarioConfig) -> PlantConfig:
    """The plant's start settings for the scenario's drift (its catalog entry's; a CommonRoad STD car's rear wheel
    at the slip of its own drift at the scenario's left radius and sideslip)."""
    return plant.plant_type.started_in_drift(plant, scenario.left_radius_m, scenario.sideslip_rad)


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
    if model == current.model and (not current.plant_type.own_car or vehicle_id == current.commonroad_vehicle):
        return
    from driftlab.core.plants import plant_type

    entry = plant_type(model)
    if entry is not None and isinstance(vehicle_id, int) and not isinstance(vehicle_id, bool):
        sections["plant"] = entry.preset(vehicle_id)
    # else: PlantConfig refuses the value, naming it


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
        config = replace(config, mpc=config.plant.plant_type.controller())
    to_fit = set(config.to_fit) - ({MODEL_FIT} if "vehicle" in changes else set())
    refit = ("vehicle" not in changes and bool({"plant", "scenario"} & set(changes))
             and (config.plant.plant_type.own_car or plant_switched))
    if refit:
        to_fit |= {MODEL_FIT, START_FIT}
    if "initial_rear_slip" in plant_changes:
        to_fit.discard(START_FIT)
    return _fitted_unless_costly(replace(config, to_fit=frozenset(to_fit)))


def dotted_config(document: Any) -> dict[str, Any]:
    """A config document as flat dotted keys: it may be nested sections ({"plant": {"mass_scale": 1.1}}, as
    stored) or dotted keys already ({"plant.mass_scale": 1.1}, as posted or given to ``--set``)."""
    if not isinstance(document, dict):
        raise ConfigError("config must be an object")
    if document and all(isinstance(v, dict) for v in document.values()):
        return {f"{section}.{k}": v for section, values in document.items() for k, v in values.items()}
    return dict(document)


def config_from_document(document: Any) -> EpisodeConfig:
    """The episode config a stored or posted document describes (see :func:`dotted_config`); validated."""
    return apply_overrides(EpisodeConfig(), dotted_config(document or {}))


def check_json_types(values: dict[str, Any]) -> None:
    """Refuse a JSON value of the wrong type for its config key (flat dotted keys or nested sections): a number
    given as text ("0.03"), a switch as 1. The CLI's ``--set`` parses text; a JSON document states its types.
    Unknown keys pass here: :func:`apply_overrides` refuses them, naming them.

    Raises:
        ConfigError: naming the key and the JSON type it needs.
    """
    defaults = config_keys()
    for key, raw in dotted_config(values).items():
        if key not in defaults:
            continue
        current = defaults[key]
        if isinstance(current, bool):
            ok, kind = isinstance(raw, bool), "true or false"
        elif isinstance(current, int):
            ok, kind = isinstance(raw, int) and not isinstance(raw, bool), "an integer"
        elif isinstance(current, float):
            ok, kind = isinstance(raw, (int, float)) and not isinstance(raw, bool), "a number"
        else:
            ok, kind = isinstance(raw, str), "a string"
        if not ok:
            raise ConfigError(f"{key} must be {kind} (a JSON value of that type), got {raw!r}", field=key)


def config_to_dict(config: EpisodeConfig) -> dict[str, dict[str, Any]]:
    """Nested plain dict {section: {field: value}}, without what is still to be fitted (:func:`fitted`): parsed
    again, it is to be fitted again."""
    out = {f.name: {g.name: getattr(getattr(config, f.name), g.name) for g in fields(getattr(config, f.name))}
           for f in fields(config) if is_dataclass(getattr(config, f.name))}
    return without_keys(out, config.to_fit)


def without_keys(document: dict[str, dict[str, Any]], keys: frozenset[str]) -> dict[str, dict[str, Any]]:
    """A nested config document without ``keys`` (a section, "vehicle", or a dotted key, "plant.initial_rear_slip"):
    a config still to be fitted compares with a stored, fitted one of the same settings as this."""
    out = {section: dict(values) for section, values in document.items() if section not in keys}
    for key in keys:
        section, _, name = key.partition(".")
        if name and section in out:
            out[section].pop(name, None)
    return out


def config_from_dict(data: dict[str, dict[str, Any]], base: EpisodeConfig | None = None) -> EpisodeConfig:
    """Inverse of :func:`config_to_dict`; missing keys keep ``base``'s values."""
    flat = {}
    for section, values in data.items():
        if not isinstance(values, dict):
            raise ConfigError(f"config.{section} must be an object of field values")
        flat.update({f"{section}.{k}": v for k, v in values.items()})
    return apply_overrides(base or EpisodeConfig(), flat)


def config_keys() -> dict[str, Any]:
    """Every dotted key with its default value (for help texts and the README)."""
    return {f"{s}.{k}": v for s, section in config_to_dict(EpisodeConfig()).items() for k, v in section.items()}
