"""What DriftLab knows of one plant model (``plant.model``): one object per model, the one place that says how
to step it, where it starts, which controller's model and weights it comes with, and where it can drift. The
episode loop, the config parser, the drivability check and the CLI ask the plant's kind (driftlab.core.plants)
and never test its name.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.errors import NoEquilibriumError
from driftlab.core.mpc_config import MpcConfig
from driftlab.core.plant import PlantConfig
from driftlab.core.vehicle import VehicleParams, pack_params


class PlantType(ABC):
    """A plant model. Subclasses override what differs; the defaults fit a plant that steps on its own (a user's
    registered plant): the paper's Table I car as the controller's model, the default weights, and a drift known
    only through that model.

    Attributes:
        name: its ``plant.model``.
        own_car: it brings its own tyres, loads and yaw inertia (a CommonRoad car): DriftLab's tyre and load
            settings stay off, and its mass scale carries its yaw inertia.
        fits_model: the controller's model is fitted to the plant's own drift at each job's drift
            (:meth:`model_vehicle` solves the plant's drift family): a config is fitted when it first runs, not
            when it is parsed (driftlab.core.configure.fitted), and :meth:`check_fit` tells before whether it can be.
        preset_name: the ``--plant`` preset that starts from it (None: reached only through ``plant.model``).
        default_sideslip_rad: the sideslip its preset drifts at, or None for the scenario's default.
        local_phase: new jobs start their seed points near the uncorrected model (TuningSpec.local_phase).
        theta_bounds: where a new job's search box differs from the paper's (driftlab.core.tuning.DEFAULT_BOUNDS).
        not_drivable_hint: what to change, appended to the message when the controller's model cannot drift.
        wheel_loads: it has a load on each wheel and may lift one (CommonRoad's MB): ``plant.wheel_liftoff`` applies.
    """

    name: str = ""
    own_car: bool = False
    wheel_loads: bool = False
    fits_model: bool = False
    preset_name: str | None = None
    default_sideslip_rad: float | None = None
    local_phase: bool = False
    theta_bounds: dict[str, tuple[float, float]] = {}  # noqa: RUF012  # read only
    not_drivable_hint: str = ""

    def preset(self, vehicle_id: int | None = None) -> PlantConfig:
        """Its configuration as ``--plant NAME`` starts it (``vehicle_id``: a parameter set, where it has them)."""
        return PlantConfig(model=self.name)

    def check(self, config: PlantConfig) -> None:  # noqa: B027  # every setting is fine unless a plant says so
        """Raise ConfigError naming the field for a setting this plant cannot take."""

    @abstractmethod
    def build(self, config: PlantConfig, model_vehicle: VehicleParams) -> Any:
        """What the episode loop steps (see :class:`driftlab.core.plant.Plant` for the interface)."""

    def model_vehicle(self, config: PlantConfig, radius_m: float, sideslip_rad: float) -> VehicleParams:
        """The controller's vehicle for this plant driving (radius, sideslip)."""
        return VehicleParams()

    def check_fit(self, config: PlantConfig, radius_m: float, sideslip_rad: float) -> None:  # noqa: B027
        """Raise ConfigError (OutsideDriftWindowError, naming the window) where the controller's model cannot be
        fitted at (radius, sideslip), without fitting it (a plant that :attr:`fits_model`)."""

    def started_in_drift(self, config: PlantConfig, radius_m: float, sideslip_rad: float) -> PlantConfig:
        """``config`` with its start settings for an episode that begins in the plant's own drift at (radius,
        sideslip); most plants need none."""
        return config

    def controller(self) -> MpcConfig:
        """The default controller's weights for this plant."""
        return MpcConfig()

    def steering_reach_rad(self, config: PlantConfig) -> float | None:
        """How far the car ``config`` sets steers either way [rad], where the plant says (None: unknown). A
        calibration also searches with the controller steering that far (driftlab.core.calibration_run)."""
        return None

    def model_reason(self, vehicle: VehicleParams, radius_m: float, sideslip_rad: float, circle: str) -> str | None:
        """Why the controller's model ``vehicle`` (or, for a plant whose model is refitted at each drift, the model
        a job at this drift would get) has no countersteer drift on this circle, or None."""
        return model_reason(vehicle, radius_m, sideslip_rad, circle)

    def plant_reason(self, config: PlantConfig, vehicle: VehicleParams | None, radius_m: float, sideslip_rad: float,
                     circle: str) -> str | None:
        """Why the plant itself cannot hold a countersteer drift on this circle, or None (unknown counts as
        drivable: only the controller's model is checked then). ``vehicle``: the controller's (None: still to be
        fitted)."""
        return None

    def equilibrium_summary(self, config: PlantConfig, vehicle: VehicleParams, radius_m: float,
                            beta_rad: float) -> dict[str, Any] | None:
        """The plant's own drift at (radius, beta) as `driftlab equilibrium --plant` prints it (None: unknown)."""
        return None

    def window_reason(self, config: PlantConfig, vehicle: VehicleParams | None, radius_m: float, low_rad: float,
                      high_rad: float, elsewhere_radii_m: tuple[float, ...] = ()) -> str:
        """Why a job of this plant (its controller's model ``vehicle``; None: fitted at each drift) drifts no
        sideslip of [low, high] on a circle of ``radius_m``: one sentence (naming, where the plant knows, which of
        ``elsewhere_radii_m`` it drifts)."""
        return (f"neither circle of {radius_m:g} m has a sideslip in {low_rad:.2f}-{high_rad:.2f} rad at which both "
                f"the plant and the controller's model have a countersteer drift equilibrium")


def model_reason(vehicle: VehicleParams, radius_m: float, sideslip_rad: float, circle: str) -> str | None:
    """Why the controller's model has no countersteer drift equilibrium on this circle, or None."""
    try:
        drift_equilibrium(radius_m, -abs(sideslip_rad), pack_params(vehicle))
    except NoEquilibriumError:
        return (f"config is not drivable: the controller's model has no countersteer drift equilibrium on the "
                f"{circle} circle (scenario radius {radius_m:g} m, sideslip {abs(sideslip_rad):g} rad)")
    return None


class ExternalPlantType(PlantType):
    """A plant registered by a factory (``register_plant``, or an installed package's entry point in the group
    ``driftlab.plants`` that names a factory rather than a :class:`PlantType`)."""

    def __init__(self, name: str, factory) -> None:
        self.name = name
        self._factory = factory

    def build(self, config: PlantConfig, model_vehicle: VehicleParams) -> Any:
        return self._factory(config)
