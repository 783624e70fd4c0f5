"""The plant catalog (driftlab.core.plants): one object per plant model, and nothing outside it tests a plant's
name."""

import re
from dataclasses import replace
from pathlib import Path

import pytest

from driftlab.core.config import EpisodeConfig
from driftlab.core.configure import apply_overrides, fitted, preset_config
from driftlab.core.errors import ConfigError
from driftlab.core.mpc_config import MpcConfig
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
    assert std.preset(3).substep_s == 0.002
    assert plant_type("driftlab").local_phase and not std.local_phase
    assert preset_config("commonroad_std").mpc == std.controller() != MpcConfig()
    assert plant_type("nonexistent") is None
    # How far each car steers (the package's steering.max), which a calibration also tries the controller with.
    assert std.steering_reach_rad(std.preset(2)) == 1.066 and mb.steering_reach_rad(mb.preset(3)) == 1.023
    assert plant_type("driftlab").steering_reach_rad(PlantConfig()) is None


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


def test_a_commonroad_variant_drives_its_own_scaled_parameters():
    from driftlab.core.commonroad.equilibrium import commonroad_drifts
    from driftlab.core.commonroad.parameters import CR_CG_HEIGHT, CR_MASS, T, pack_commonroad, package_parameters
    from driftlab.core.plants import CommonRoadVariant

    scales = {"m": 1.3, "h_s": 1.2, "tire.p_dx1": 0.85, "tire.p_dy1": 0.85}
    register_plant("scaled_bmw", CommonRoadVariant(scales))
    variant = plant_type("scaled_bmw")
    car, published = variant.car(2), package_parameters(2)
    packed, packed_published = pack_commonroad(car), pack_commonroad(2)
    assert packed[CR_MASS] == pytest.approx(1.3 * published.m) and packed[CR_CG_HEIGHT] == pytest.approx(
        1.2 * published.h_s)
    assert packed[T["p_dy1"]] == pytest.approx(0.85 * published.tire.p_dy1)
    assert packed[T["p_ky1"]] == packed_published[T["p_ky1"]] and package_parameters(2).m == published.m
    # Its drift is its own: 15 % less grip drifts slower (V^2 ~ mu g R), and the controller's model follows it.
    own, bmw = commonroad_drifts(car, 44.0, 0.5)[0], commonroad_drifts(2, 44.0, 0.5)[0]
    assert own.speed_mps < bmw.speed_mps - 0.5
    config = fitted(preset_config("scaled_bmw"))
    assert config.plant.model == "scaled_bmw" and config.scenario.sideslip_rad == 0.5
    assert config.vehicle.mass_kg == pytest.approx(1.3 * published.m)
    assert config.mpc == plant_type("commonroad_std").controller()  # the base car's weights until calibrated


def test_a_variant_with_no_scales_is_its_base_car_bit_for_bit():
    from driftlab.core.config import Theta
    from driftlab.core.episode import run_episode
    from driftlab.core.plants import CommonRoadVariant

    register_plant("same_bmw", CommonRoadVariant({}))
    same, bmw = fitted(preset_config("same_bmw")), fitted(preset_config("commonroad_std"))
    assert same.vehicle == bmw.vehicle and same.mpc == bmw.mpc
    ours, theirs = run_episode(Theta(), same, seed=3), run_episode(Theta(), bmw, seed=3)
    assert ours.J == theirs.J and (ours.trajectory == theirs.trajectory).all()


def test_a_variant_refuses_a_parameter_the_package_does_not_have():
    from driftlab.core.plants import CommonRoadVariant

    register_plant("typo_bmw", CommonRoadVariant({"tire.p_dy9": 0.9}))
    with pytest.raises(ConfigError, match="p_dy9") as refused:
        preset_config("typo_bmw")
    assert refused.value.field == "plant.model"
    with pytest.raises(ConfigError, match="built on one of commonroad_std, commonroad_mb"):
        CommonRoadVariant({"m": 1.1}, base="driftlab")
    with pytest.raises(ConfigError, match="positive"):
        register_plant("negative_bmw", CommonRoadVariant({"m": -1.0}))
        preset_config("negative_bmw")


def test_a_jobs_default_search_box_is_its_plants():
    from driftlab.core.tuning import DEFAULT_BOUNDS, TuningSpec

    assert TuningSpec(config=EpisodeConfig()).bounds["k"] == DEFAULT_BOUNDS["k"]  # the paper's, on DriftLab's plant
    std = TuningSpec(config=preset_config("commonroad_std"))
    assert std.bounds["k"][0] < 0.0 < std.bounds["k"][1] and std.bounds["dV"] == (-1.0, 1.0)
    assert std.bounds["c_lr"] == DEFAULT_BOUNDS["c_lr"]
    given = TuningSpec(config=preset_config("commonroad_std"), bounds={"k": [0.0, 0.1]})
    assert given.bounds["k"] == (0.0, 0.1) and given.bounds["dV"] == (-1.0, 1.0)  # a given bound wins
    stored = TuningSpec.from_dict(TuningSpec(config=EpisodeConfig()).to_dict())
    assert stored.bounds == TuningSpec(config=EpisodeConfig()).bounds
