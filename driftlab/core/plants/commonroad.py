"""CommonRoad's vehicle models in the catalog (driftlab.core.commonroad): STD stepped inside the compiled loop, MB
and the package's own STD functions stepped from Python. Each car is a CommonRoad parameter set (2 BMW 320i, 3 VW
Vanagon), its controller's model fitted to the car's own drift (driftlab.core.commonroad.model_fit)."""

from __future__ import annotations

import importlib
from dataclasses import replace
from typing import Any

from driftlab.core.commonroad.parameters import ParameterSet
from driftlab.core.errors import ConfigError
from driftlab.core.mpc_config import MpcConfig
from driftlab.core.plant import PLANT_LIMITS, PlantConfig
from driftlab.core.plants.base import PlantType, model_reason
from driftlab.core.vehicle import VehicleParams

# Settings that shape DriftLab's own car and tyres; a CommonRoad plant has its own (PAC2002 tyres, load transfer,
# combined slip) and keeps these at 1 / off.
DRIFTLAB_ONLY: dict[str, Any] = {"yaw_inertia_scale": 1.0, "tyre_b_scale": 1.0, "tyre_c_scale": 1.0,
                                 "friction_circle": False, "load_transfer": False}


class CommonRoadPlantType(PlantType):
    """A CommonRoad model.

    Attributes:
        stepper: "module:Class" of what the loop steps (built on first use: this module imports none of them).
        multibody: the multi-body model (MB): its drift family is MB's own (driftlab.core.commonroad.mb_equilibrium),
            and its controller's model takes the rear friction circle and the car's steering answer.
        substep_s: RK4 step of its preset.
        weights: "module:function" of its default controller's weights (driftlab.core.commonroad.weights), if any.
    """

    own_car = True
    fits_model = True
    default_sideslip_rad = 0.5  # a CommonRoad car countersteers only from ~0.45 rad at 44 m (its drift family)
    # The paper's box assumes the steering feedback on the path error helps (k >= 0) and the model's drift speed is
    # within 0.3 m/s of the car's. The controller's model of a CommonRoad car is fitted to its drift at one point
    # and drifts elsewhere at other speeds, and near the edge of the model's window its path answers the feedback
    # the other way: the job searches the feedback's sign and a wider speed correction (docs/results.md,
    # "The search box of a CommonRoad car").
    theta_bounds = {"dV": (-1.0, 1.0), "k": (-0.12, 0.12)}  # noqa: RUF012  # read only

    def __init__(self, name: str, stepper: str, *, multibody: bool = False, substep_s: float = 0.002,
                 weights: str | None = None, preset_name: str | None = None) -> None:
        self.name = name
        self.stepper = stepper
        self.multibody = multibody
        self.wheel_loads = multibody
        self.substep_s = substep_s
        self.weights = weights
        self.preset_name = preset_name

    def __repr__(self) -> str:
        return f"CommonRoadPlantType({self.name!r})"

    def preset(self, vehicle_id: int | None = None) -> PlantConfig:
        """Its own car and tyres, DriftLab's actuators (30 ms / 8 rad/s steering servo, 50 ms drive), the default
        plant's per-episode variation; MB's wheels may lift off the road (PlantConfig.wheel_liftoff: in a ~1 g drift
        the published model's inner front tyre pulls the road for most of the episode)."""
        return PlantConfig(model=self.name, commonroad_vehicle=2 if vehicle_id is None else vehicle_id,
                           friction_scale=1.0, substep_s=self.substep_s, wheel_liftoff=self.wheel_loads,
                           **DRIFTLAB_ONLY)

    def check(self, config: PlantConfig) -> None:
        from driftlab.core.commonroad.parameters import check_vehicle

        check_vehicle(config.commonroad_vehicle)
        for name, value in DRIFTLAB_ONLY.items():
            if getattr(config, name) != value:
                raise ConfigError(f"plant.{name} shapes DriftLab's own plant; a CommonRoad plant has its own "
                                  f"tyres and loads (keep it at {value!r})", field=f"plant.{name}")
        if config.steer_lag_s <= 0.0:
            raise ConfigError("plant.steer_lag_s must be > 0 for a CommonRoad plant (the steering servo's time "
                              "constant)", field="plant.steer_lag_s")

    def car(self, vehicle_id: int) -> int | ParameterSet:
        """The parameter set this plant drives for ``plant.commonroad_vehicle`` (the package's, as published)."""
        return vehicle_id

    def car_name(self, vehicle_id: int) -> str:
        """The car as messages name it: "CommonRoad vehicle 3 (VW Vanagon)"."""
        from driftlab.core.commonroad.parameters import VEHICLE_NAMES

        return f"CommonRoad vehicle {vehicle_id} ({VEHICLE_NAMES.get(vehicle_id, '?')})"

    def build(self, config: PlantConfig, model_vehicle: VehicleParams) -> Any:
        """The stepper of ``config``'s car (its parameter set, :meth:`car`): the class ``stepper`` names, called
        with the config and the car."""
        module_name, _, attribute = self.stepper.partition(":")
        return getattr(importlib.import_module(module_name), attribute)(config, self.car(config.commonroad_vehicle))

    def model_vehicle(self, config: PlantConfig, radius_m: float, sideslip_rad: float) -> VehicleParams:
        from driftlab.core.commonroad.model_fit import fitted_model_vehicle

        return fitted_model_vehicle(config.commonroad_vehicle, radius_m, sideslip_rad, self,
                                    drive_coupling=config.model_drive_coupling)

    def check_fit(self, config: PlantConfig, radius_m: float, sideslip_rad: float) -> None:
        from driftlab.core.commonroad.model_fit import check_fittable

        check_fittable(config.commonroad_vehicle, radius_m, sideslip_rad, self)

    def started_in_drift(self, config: PlantConfig, radius_m: float, sideslip_rad: float) -> PlantConfig:
        """The rear wheel starts at the slip ratio of the car's own (left-hand) drift there: any other start is a
        step of the rear force the first seconds spend recovering from, or do not (the VW Vanagon drifts at 0.62
        rad, 44 m with its rear wheel at -0.93; started at -0.5 it grips up within 3 s). The multi-body car
        starts every wheel in its own drift already (driftlab.core.commonroad.mb_plant.CommonRoadMbPlant)."""
        if self.multibody:
            return config
        family = self.drifts(config.commonroad_vehicle, radius_m, sideslip_rad, False, config.friction_scale,
                             config.mass_scale)
        if not family:
            return config
        low, high = PLANT_LIMITS["initial_rear_slip"]
        return replace(config, initial_rear_slip=min(max(round(family[0].rear_slip, 4), low), high))

    def controller(self) -> MpcConfig:
        if self.weights is None:
            return MpcConfig()
        module_name, _, attribute = self.weights.partition(":")
        return getattr(importlib.import_module(module_name), attribute)()

    def steering_reach_rad(self, config: PlantConfig) -> float | None:
        """The car's own (the package's ``steering.max``: 1.066 rad for the BMW 320i, 1.023 for the VW Vanagon)."""
        from driftlab.core.commonroad.parameters import steering_reach_rad

        return steering_reach_rad(self.car(config.commonroad_vehicle))

    def drifts(self, vehicle_id: int, radius_m: float, sideslip_rad: float, right: bool = False,
               friction_scale: float = 1.0, mass_scale: float = 1.0) -> tuple:
        """The car's steady drifts at (radius, |sideslip|), left- or ``right``-hand, the main one first."""
        if self.multibody:
            from driftlab.core.commonroad.mb_equilibrium import mb_main_drift

            main = mb_main_drift(self.car(vehicle_id), radius_m, sideslip_rad, right, friction_scale, mass_scale)
            return () if main is None else (main,)
        from driftlab.core.commonroad.equilibrium import commonroad_drifts

        return commonroad_drifts(self.car(vehicle_id), radius_m, sideslip_rad, friction_scale, mass_scale, right=right)

    def model_reason(self, vehicle: VehicleParams, radius_m: float, sideslip_rad: float, circle: str) -> str | None:
        """The model fitted at another drift, with its front grip raised as a fit at this one would raise it
        (driftlab.core.commonroad.model_fit)."""
        from driftlab.core.commonroad.window import widest_front_grip

        reason = model_reason(vehicle, radius_m, sideslip_rad, circle)
        return reason and model_reason(widest_front_grip(vehicle), radius_m, sideslip_rad, circle)

    def plant_reason(self, config: PlantConfig, vehicle: VehicleParams | None, radius_m: float, sideslip_rad: float,
                     circle: str) -> str | None:
        from driftlab.core.commonroad.family import describe_family

        family = self.drifts(config.commonroad_vehicle, radius_m, sideslip_rad, circle == "right",
                             config.friction_scale, config.mass_scale)
        why = describe_family(family)
        if why is None:
            return None
        return (f"config is not drivable on the {circle} circle (scenario radius {radius_m:g} m, sideslip "
                f"{abs(sideslip_rad):g} rad): {why}; try another scenario.sideslip_rad (`driftlab equilibrium "
                f"--plant {config.model}` prints where the car countersteers)")

    def window_reason(self, config: PlantConfig, vehicle: VehicleParams | None, radius_m: float, low_rad: float,
                      high_rad: float, elsewhere_radii_m: tuple[float, ...] = ()) -> str:
        """Its tyres, its engine or the controller's model (driftlab.core.commonroad.window), and which of the
        other circles it drifts."""
        from driftlab.core.commonroad.window import elsewhere_text, no_drift_reason

        vehicle_id = config.commonroad_vehicle
        elsewhere = elsewhere_text(self, vehicle_id, radius_m, elsewhere_radii_m)
        return no_drift_reason(self, vehicle_id, radius_m) + (f"; {elsewhere}" if elsewhere else "")

    def equilibrium_summary(self, config: PlantConfig, vehicle: VehicleParams, radius_m: float,
                            beta_rad: float) -> dict[str, Any] | None:
        from driftlab.core.commonroad.family import family_summary

        return family_summary(self, config, radius_m, beta_rad)


COMMONROAD_BUILT_INS = (
    CommonRoadPlantType("commonroad_std", "driftlab.core.commonroad.plant:CommonRoadStdPlant", substep_s=0.002,
                        weights="driftlab.core.commonroad.weights:std_weights", preset_name="commonroad_std"),
    # MB at 3 ms (17 RK4 substeps a control step): its fastest mode, a front wheel's speed, is -260 to -350 1/s in
    # the drift and ~ -580 1/s at 9 m/s (docs/results.md), inside RK4's real-axis bound 2.785 / h = 950 1/s above
    # the failure limit's 8 m/s; a control step lands within 2e-5 m and rad of a 0.1 ms reference.
    CommonRoadPlantType("commonroad_mb", "driftlab.core.commonroad.mb_plant:CommonRoadMbPlant", multibody=True,
                        substep_s=0.003, weights="driftlab.core.commonroad.weights:mb_weights",
                        preset_name="commonroad_mb"),
    # The package's own Python functions behind the same actuators: the reference STD is checked against.
    CommonRoadPlantType("commonroad_std_reference", "driftlab.core.commonroad.reference:ReferenceStdPlant"),
)


class CommonRoadVariant(CommonRoadPlantType):
    """A car of one's own built on a CommonRoad model and parameter set: some of the set's parameters scaled (mass,
    CG height, tyre friction, ...). What a user registers under the entry-point group ``driftlab.plants``
    (docs/calibration.md, "Bring your own car"). It steps, drifts and has its controller's model fitted as its
    base model does, from its own parameters; it starts from the base car's weights until ``driftlab calibrate``
    stores a profile of its own.

    Args:
        scales: a parameter's name in the package's object (``"m"``, ``"h_s"``, ``"tire.p_dy1"``) -> its factor.
        base: the CommonRoad model it is stepped with (``commonroad_std`` or ``commonroad_mb``).
        name: its ``plant.model`` (the entry point's name when empty).
    """

    def __init__(self, scales: dict[str, float], base: str = "commonroad_std", name: str = "") -> None:
        model = next((entry for entry in COMMONROAD_BUILT_INS if entry.name == base), None)
        if model is None:
            names = ", ".join(entry.name for entry in COMMONROAD_BUILT_INS)
            raise ConfigError(f"a CommonRoad variant is built on one of {names}, not {base!r}",
                              field="plant.model")
        super().__init__(name, model.stepper, multibody=model.multibody, substep_s=model.substep_s,
                         weights=model.weights)
        self.base = base
        self.scales = tuple(sorted((str(key), float(value)) for key, value in scales.items()))

    def __repr__(self) -> str:
        return f"CommonRoadVariant({self.name!r}, base={self.base!r}, scales={dict(self.scales)!r})"

    def car(self, vehicle_id: int) -> ParameterSet:
        return ParameterSet(vehicle_id, self.scales)

    def car_name(self, vehicle_id: int) -> str:
        """By its registered name: "light_bmw (CommonRoad's BMW 320i, scaled)"."""
        from driftlab.core.commonroad.parameters import VEHICLE_NAMES

        return f"{self.name} (CommonRoad's {VEHICLE_NAMES.get(vehicle_id, f'vehicle {vehicle_id}')}, scaled)"

    def check(self, config: PlantConfig) -> None:
        super().check(config)
        self.car(config.commonroad_vehicle)  # refuses a scaled parameter the package's set does not have
