"""The plant catalog (driftlab.core.plants): one object per plant model, and nothing outside it tests a plant's
name."""

import re
from dataclasses import replace
from pathlib import Path

import pytest

from driftlab.core.config import EpisodeConfig, apply_overrides
from driftlab.core.errors import ConfigError
from driftlab.core.mpc import MpcConfig
from driftlab.core.plant import PlantConfig
from driftlab.core.plants import CommonRoadPlantType, PlantType, plant_type, register_plant
from driftlab.core.vehicle import VehicleParams

PACKAGE = Path(__file__).resolve().parents[2] / "driftlab"
NAME_TEST = re.compile(r"""\.model\s*(==|!=|in)\s*[("']|model\s*==\s*["']|startswith\(\s*["']commonroad""")


def test_nothing_outside_the_catalog_tests_a_plants_name():
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        if "plants" in path.relative_to(PACKAGE).parts:
            continue
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if NAME_TEST.search(line) and "estimator_model" not in line:
                offenders.append(f"{path.relative_to(PACKAGE)}:{number}: {line.strip()}")
    assert not offenders, offenders


def test_each_built_in_plant_is_one_catalog_entry_with_its_presets():
    std, mb = plant_type("commonroad_std"), plant_type("commonroad_mb")
    assert isinstance(std, CommonRoadPlantType) and not std.multibody and mb.multibody
    assert PlantConfig.commonroad_std(3) == std.preset(3) and std.preset(3).substep_s == 0.002
    assert plant_type("driftlab").local_phase and not std.local_phase
    assert EpisodeConfig.preset("commonroad_std").mpc == std.controller() != MpcConfig()
    assert plant_type("nonexistent") is None


def test_a_plant_type_registered_by_a_user_brings_its_own_model_and_weights():
    class Heavier(PlantType):
        """DriftLab's plant, 20 % heavier, with its own controller's weights."""

        def preset(self, vehicle_id=None):
            return PlantConfig(model=self.name, mass_scale=1.2)

        def build(self, config, model_vehicle):
            return plant_type("driftlab").build(replace(config, model="driftlab"), model_vehicle)

        def model_vehicle(self, config, radius_m, sideslip_rad):
            return replace(VehicleParams(), mass_kg=VehicleParams().mass_kg * 1.2)

        def controller(self):
            return replace(MpcConfig(), q_sideslip=500.0)

    register_plant("heavier", Heavier)
    config = apply_overrides(EpisodeConfig(), {"plant.model": "heavier"})
    assert config.plant.mass_scale == 1.2 and config.mpc.q_sideslip == 500.0
    assert config.vehicle.mass_kg == pytest.approx(VehicleParams().mass_kg * 1.2)
    with pytest.raises(ConfigError, match="built in"):
        register_plant("commonroad_mb", Heavier)
