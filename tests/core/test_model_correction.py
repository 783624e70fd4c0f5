"""theta's model corrections: the controller's model friction and tyre C, learned alongside the paper's theta."""

import pytest

from driftlab.core.config import EpisodeConfig, Theta
from driftlab.core.configure import apply_overrides, preset_config
from driftlab.core.episode import run_episode
from driftlab.core.errors import ConfigError
from driftlab.core.tuning import MODEL_BOUNDS, TuningSpec


def test_the_corrections_scale_the_models_friction_and_tyre_c_only():
    vehicle = EpisodeConfig().vehicle
    model = Theta(model_mu_scale=1.1, model_c_scale=0.9).model_vehicle(vehicle)
    assert model.friction == pytest.approx(0.85 * 1.1) and model.tyre_c == pytest.approx(1.4478 * 0.9)
    assert (model.mass_kg, model.tyre_b, model.cg_to_front_m) == (vehicle.mass_kg, vehicle.tyre_b,
                                                                  vehicle.cg_to_front_m)
    assert Theta().model_vehicle(vehicle) is vehicle


def test_knowing_the_plants_tyre_c_brings_the_car_onto_the_line():
    """Nominal plant with C x 1.2: the model as configured drifts the 8 ~1.3 m off the line; corrected by the
    plant's own factor the offset-free target is the plant's drift and the error falls below 0.5 m."""
    config = apply_overrides(preset_config(plant="nominal"), {"plant.tyre_c_scale": 1.2})
    plain = run_episode(Theta(), config)
    corrected = run_episode(Theta(model_c_scale=1.2), config)
    assert plain.completed and corrected.completed
    assert plain.metrics.mean_abs_e_m > 1.0 > 0.5 > corrected.metrics.mean_abs_e_m
    assert corrected.J < plain.J


def test_a_correction_outside_the_cars_range_names_theta():
    with pytest.raises(ConfigError, match="theta.model_mu_scale / theta.model_c_scale.*tyre_c"):
        Theta(model_c_scale=1.9).model_vehicle(EpisodeConfig().vehicle)
    with pytest.raises(ConfigError, match="model_c_scale"):
        Theta(model_c_scale=2.5)


def test_a_job_learns_the_corrections_unless_told_not_to():
    assert set(MODEL_BOUNDS) <= set(TuningSpec().bounds)
    paper = TuningSpec(model_correction=False)
    assert set(paper.bounds) == {"c_lr", "c_rl", "dV", "k"}
    with pytest.raises(ConfigError, match="bounds.model_c_scale.*model_correction"):
        TuningSpec(model_correction=False, bounds={"model_c_scale": [0.9, 1.1]})
    # every corner of the box must be a car: C x 1.8 on a vehicle with C 2.0 is not
    with pytest.raises(ConfigError, match="tyre_c"):
        TuningSpec(bounds={"model_c_scale": [0.9, 1.8]}, config=apply_overrides(EpisodeConfig(),
                                                                                {"vehicle.tyre_c": 2.0}))
    assert TuningSpec.from_dict(TuningSpec().to_dict()) == TuningSpec()


def test_a_job_with_the_corrections_starts_from_the_untuned_theta():
    assert TuningSpec().initial_points == [Theta().as_dict()]
    assert TuningSpec(model_correction=False).initial_points == []
    assert TuningSpec(bounds={"k": [0.06, 0.1]}).initial_points == []  # outside the box: not asked


def test_the_local_phase_is_on_for_driftlabs_plants_and_off_for_a_commonroad_car_unless_told():
    default = TuningSpec()
    assert default.local_phase and default.optimizer_options["local_points"] == 11
    assert default.optimizer_options["local_radius"] == {name: 0.05 for name in MODEL_BOUNDS}
    std = TuningSpec(config=preset_config("commonroad_std"))
    assert std.local_phase is False and "local_points" not in std.optimizer_options
    assert TuningSpec(config=preset_config("commonroad_std"), local_phase=True).local_phase
    assert "local_points" not in TuningSpec(model_correction=False).optimizer_options  # four dimensions: no phase
    assert TuningSpec.from_dict(std.to_dict()).local_phase is False  # stored as what it resolved to
    with pytest.raises(ConfigError, match="local_phase must be true or false"):
        TuningSpec(local_phase="yes")


def test_a_corrected_models_right_drift_is_its_left_drift_mirrored_bit_for_bit():
    """Every evaluation's theta is a new model built in each worker: on equal radii with no per-side offsets its
    right equilibrium is taken as the left one mirrored (one solve, not two), and it is exactly what the full
    solve of the right side gives; with unequal radii both are solved."""
    from driftlab.core.controller import _reference_equilibria
    from driftlab.core.equilibrium import drift_equilibrium
    from driftlab.core.vehicle import pack_params

    config = EpisodeConfig()
    scenario = config.scenario
    for mu, c in ((0.87, 1.21), (1.13, 0.93)):
        vehicle = Theta(model_mu_scale=mu, model_c_scale=c).model_vehicle(config.vehicle)
        left, right = _reference_equilibria(vehicle, scenario.left_radius_m, scenario.right_radius_m,
                                            scenario.sideslip_rad)
        assert right == drift_equilibrium(scenario.right_radius_m, abs(scenario.sideslip_rad),
                                          pack_params(vehicle, right=True))
        assert right == left.mirrored()
        left, right = _reference_equilibria(vehicle, 44.0, 36.0, scenario.sideslip_rad)
        assert right == drift_equilibrium(36.0, abs(scenario.sideslip_rad), pack_params(vehicle, right=True))
        assert right.speed_mps < left.speed_mps
