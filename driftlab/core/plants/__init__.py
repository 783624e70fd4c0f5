"""The plant catalog: every plant an episode can step, one :class:`PlantType` each (its stepper, presets, start,
drift family, the controller's model and weights fitted to it). Built in: DriftLab's own plant (``driftlab``,
presets ``default`` and ``nominal``) and CommonRoad's STD and MB; more are registered in Python
(:func:`register_plant`) or by an installed package under the entry-point group ``driftlab.plants`` (a
:class:`PlantType` instance or subclass, or a factory ``config -> stepper``), never from a request: a REST client
can only name what is installed.
"""

from __future__ import annotations

from collections.abc import Callable
from importlib.metadata import entry_points

from driftlab.core.errors import ConfigError
from driftlab.core.plant import PlantConfig
from driftlab.core.plants.base import ExternalPlantType, PlantType, model_reason
from driftlab.core.plants.commonroad import COMMONROAD_BUILT_INS, DRIFTLAB_ONLY, CommonRoadPlantType, CommonRoadVariant
from driftlab.core.plants.driftlab_plant import DriftLabPlantType

__all__ = ["DRIFTLAB_ONLY", "CommonRoadPlantType", "CommonRoadVariant", "ExternalPlantType", "PlantType",
           "built_in", "built_in_names", "check_plant", "entry_of", "installed_names", "make_plant", "model_reason",
           "plant_type", "preset_types", "register_plant"]

_BUILT_IN: dict[str, PlantType] = {entry.name: entry for entry in (DriftLabPlantType(), *COMMONROAD_BUILT_INS)}
_REGISTERED: dict[str, PlantType] = {}


def built_in_names() -> tuple[str, ...]:
    return tuple(_BUILT_IN)


def built_in(name: str) -> PlantType:
    """A built-in plant type by name (KeyError for any other name)."""
    return _BUILT_IN[name]


def register_plant(name: str, plant: PlantType | Callable) -> None:
    """``plant``: a :class:`PlantType`, or a factory ``config -> stepper`` with ``kind = PLANT_EXTERNAL``,
    ``start_state(loop_state)`` (the full state from the loop's eight, X_POS ... DRIVE; own states appended) and
    ``step(state, steer_cmd_rad, drive_cmd_n, duration_s)`` (a new state, the loop's eight first)."""
    if name in _BUILT_IN:
        raise ConfigError(f"plant.model {name!r} is built in")
    _REGISTERED[name] = _as_type(name, plant)


def _as_type(name: str, plant: object) -> PlantType:
    if isinstance(plant, type) and issubclass(plant, PlantType):
        plant = plant()
    if isinstance(plant, PlantType):
        if not plant.name:
            plant.name = name
        return plant
    return ExternalPlantType(name, plant)


def plant_type(name: str) -> PlantType | None:
    """The plant type ``plant.model`` names: built in, registered, or an installed entry point; None if none is."""
    kind = _BUILT_IN.get(name) or _REGISTERED.get(name)
    if kind is None:
        found = [e for e in entry_points(group="driftlab.plants") if e.name == name]
        if found:
            kind = _REGISTERED[name] = _as_type(name, found[0].load())
    return kind


def installed_names() -> tuple[str, ...]:
    """The plants registered in this process or installed under the entry-point group ``driftlab.plants`` (not
    loaded: a name costs nothing until a config names it)."""
    names = dict.fromkeys(_REGISTERED)
    names.update(dict.fromkeys(e.name for e in entry_points(group="driftlab.plants") if e.name not in _BUILT_IN))
    return tuple(names)


def preset_types() -> dict[str, PlantType]:
    """The kinds that a ``--plant`` preset starts from, by preset name."""
    return {entry.preset_name: entry for entry in _BUILT_IN.values() if entry.preset_name is not None}


def entry_of(config: PlantConfig) -> PlantType:
    """The catalog entry of the plant ``config.model`` names.

    Raises:
        ConfigError: ``model`` names no plant (built in, registered or installed).
    """
    found = plant_type(config.model)
    if found is None:
        raise ConfigError(f"plant.model must be one of {', '.join(built_in_names())} or a registered plant, "
                          f"got {config.model!r}", field="plant.model")
    return found


def check_plant(config: PlantConfig) -> PlantType:
    """``config``'s entry, once its settings are checked against what that plant can take (PlantType.check); the
    check a config gets at the edge where it is parsed (driftlab.core.configure).

    Raises:
        ConfigError: naming the field.
    """
    entry = entry_of(config)
    entry.check(config)
    if config.wheel_liftoff and not entry.wheel_loads:
        raise ConfigError(f"plant.wheel_liftoff applies to a plant with wheel loads (CommonRoad's MB); "
                          f"plant.model {config.model!r} has none: keep it false", field="plant.wheel_liftoff")
    return entry


def make_plant(config: PlantConfig, model_vehicle):
    """What the episode loop steps for ``config`` (DriftLab's own plant, a CommonRoad model, a registered one)."""
    return entry_of(config).build(config, model_vehicle)
