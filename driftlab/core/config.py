"""The one configuration schema shared by the CLI, the REST API and storage: plain data.

An :class:`EpisodeConfig` groups frozen sections, each checking its own ranges. Every value is reachable by a dotted
key (``plant.friction_scale``, ``mpc.q_sideslip``, ``vehicle.mass_kg`` ...); parsing a document or dotted keys,
the presets and the checks against the plant catalog are driftlab.core.configure's (importing this module loads no
plant, solver or controller), and :func:`config_to_dict` gives the plain JSON document back.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any

from driftlab.core.errors import ConfigError
from driftlab.core.mpc_config import MpcConfig
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
        to_fit: what is still to be fitted to the plant before the config runs (:data:`MODEL_FIT`,
            :data:`START_FIT`; driftlab.core.configure.fitted). Parsing does no physics: a CommonRoad car's model is
            fitted to its drift when the config first runs (a job's when a runner claims it, and stored with the
            job), and a config document leaves out what is still to be fitted (:func:`config_to_dict`).
    """

    vehicle: VehicleParams = field(default_factory=VehicleParams)
    plant: PlantConfig = field(default_factory=PlantConfig)
    mpc: MpcConfig = field(default_factory=MpcConfig)
    scenario: ScenarioConfig = field(default_factory=ScenarioConfig)
    failure: FailureLimits = field(default_factory=FailureLimits)
    to_fit: frozenset[str] = frozenset()


    # else: PlantConfig refuses the value, naming it


def dotted_config(document: Any) -> dict[str, Any]:
    """A config document as flat dotted keys: it may be nested sections ({"plant": {"mass_scale": 1.1}}, as
    stored) or dotted keys already ({"plant.mass_scale": 1.1}, as posted or given to ``--set``)."""
    if not isinstance(document, dict):
        raise ConfigError("config must be an object")
    if document and all(isinstance(v, dict) for v in document.values()):
        return {f"{section}.{k}": v for section, values in document.items() for k, v in values.items()}
    return dict(document)


def check_json_types(values: dict[str, Any]) -> None:
    """Refuse a JSON value of the wrong type for its config key (flat dotted keys or nested sections): a number
    given as text ("0.03"), a switch as 1. The CLI's ``--set`` parses text; a JSON document states its types.
    Unknown keys pass here: driftlab.core.configure.apply_overrides refuses them, naming them.

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
    """Nested plain dict {section: {field: value}}, without what is still to be fitted
    (driftlab.core.configure.fitted): parsed again, it is to be fitted again."""
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


def config_keys() -> dict[str, Any]:
    """Every dotted key with its default value (for help texts and the README)."""
    return {f"{s}.{k}": v for s, section in config_to_dict(EpisodeConfig()).items() for k, v in section.items()}
