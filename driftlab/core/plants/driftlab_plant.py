"""DriftLab's own plant (driftlab.core.plant) in the catalog: the paper's car with what its model leaves out."""

from __future__ import annotations

from typing import Any

from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.errors import ConfigError, NoEquilibriumError
from driftlab.core.plant import Plant, PlantConfig
from driftlab.core.plants.base import PlantType
from driftlab.core.vehicle import VehicleParams


class DriftLabPlantType(PlantType):
    name = "driftlab"
    preset_name = "default"
    local_phase = True
    not_drivable_hint = ("; change the plant (e.g. plant.friction_scale, plant.tyre_c_scale, plant.cg_height_m) or "
                         "the scenario")

    def preset(self, vehicle_id: int | None = None) -> PlantConfig:
        return PlantConfig()

    def check(self, config: PlantConfig) -> None:
        if config.model_drive_coupling:
            raise ConfigError("plant.model_drive_coupling fits a CommonRoad car's model; DriftLab's plant comes with "
                              "the paper's (keep it false)", field="plant.model_drive_coupling")

    def build(self, config: PlantConfig, model_vehicle: VehicleParams) -> Plant:
        return Plant(config, model_vehicle)

    def plant_reason(self, config: PlantConfig, vehicle: VehicleParams | None, radius_m: float, sideslip_rad: float,
                     circle: str) -> str | None:
        own_car = config.packed_params(VehicleParams() if vehicle is None else vehicle)  # Table I: nothing to fit
        try:
            drift_equilibrium(radius_m, -abs(sideslip_rad), own_car)
        except NoEquilibriumError:
            return (f"config is not drivable: the plant has no countersteer drift equilibrium on the {circle} circle "
                    f"(scenario radius {radius_m:g} m, sideslip {abs(sideslip_rad):g} rad){self.not_drivable_hint}")
        return None

    def equilibrium_summary(self, config: PlantConfig, vehicle: VehicleParams, radius_m: float,
                            beta_rad: float) -> dict[str, Any] | None:
        try:
            return drift_equilibrium(radius_m, beta_rad, config.packed_params(vehicle)).as_dict()
        except NoEquilibriumError as exc:
            return {"error": str(exc)}
