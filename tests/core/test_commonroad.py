"""CommonRoad's STD as a plant: the compiled port equals the package (the reference), the plant's drift family
matches the published parameter set's numbers, the controller's model sits at the car's drift, and the config
refuses what cannot drift."""

import json
import re
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from vehiclemodels.vehicle_dynamics_std import vehicle_dynamics_std

from driftlab.core.commonroad.equilibrium import commonroad_drifts, describe_family, frozen_front_wheel_drifts
from driftlab.core.commonroad.family import sideslip_window
from driftlab.core.commonroad.model_fit import _placed_at_drift, fitted_model_vehicle
from driftlab.core.commonroad.parameters import (
    _vehiclemodels,
    commonroad_model_vehicle,
    pack_commonroad,
    package_parameters,
)
from driftlab.core.commonroad.std import std_derivatives
from driftlab.core.commonroad.weights import std_weights
from driftlab.core.config import EpisodeConfig, Theta, config_to_dict
from driftlab.core.configure import apply_overrides, config_from_document, fitted, preset_config
from driftlab.core.drivability import drivable_reason
from driftlab.core.episode import run_episode
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.errors import ConfigError, NoEquilibriumError, OutsideDriftWindowError
from driftlab.core.mpc_config import MpcConfig
from driftlab.core.plants import built_in, make_plant
from driftlab.core.vehicle import pack_params

STD, MB = built_in("commonroad_std"), built_in("commonroad_mb")


def _stepper(entry):
    """The stepper of the entry's vehicle 2 (what a car's yaw answer is read from)."""
    return entry.build(entry.preset(2), None)


@pytest.mark.parametrize("vehicle_id", [2, 3])
def test_the_compiled_std_equals_the_package_on_random_states(vehicle_id):
    p, cp = package_parameters(vehicle_id), pack_commonroad(vehicle_id)
    rng = np.random.default_rng(vehicle_id)
    for i in range(500):
        speed = rng.uniform(0.0, 0.4) if i % 10 == 0 else rng.uniform(0.5, 30.0)  # the kinematic blend too
        beta = rng.uniform(-0.8, 0.8)
        rolling = speed * np.cos(beta) / p.R_w
        x = [rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(-0.6, 0.6), speed, rng.uniform(-3, 3),
             rng.uniform(-1.5, 1.5), beta, rolling * rng.uniform(0.7, 1.3), rolling * rng.uniform(0.5, 2.5)]
        u = [rng.uniform(-2.0, 2.0), rng.uniform(-8.0, 8.0)]
        expected = np.array(vehicle_dynamics_std(list(x), u, p))
        assert np.array_equal(std_derivatives(np.array(x), np.array(u), cp), expected), (x, u)


def test_the_plants_drift_family_at_44_m():
    main = commonroad_drifts(2, 44.0, 0.5)[0]
    assert main.countersteer and abs(main.speed_mps - 20.50) <= 0.05 and abs(main.steer_rad + 0.264) <= 0.005
    assert abs(main.rear_force_n - 3636) < 10 and abs(main.rear_slip + 0.51) < 0.01
    into_turn = commonroad_drifts(2, 44.0, 0.4)
    why = describe_family(into_turn)
    assert not into_turn[0].countersteer and "steers into the turn (V 19.61 m/s, delta +0.067 rad)" in why


def test_the_low_speed_countersteer_states_hold_only_by_a_frozen_front_wheel():
    frozen = [d for d in frozen_front_wheel_drifts(2, 44.0, 0.4) if d.countersteer]
    fastest = frozen[0]
    assert 9.5 < fastest.speed_mps < 12.0 and -1.7 < fastest.rear_slip < -1.3 and fastest.front_wheel_radps < 0.0
    # The package's own STD: steady there, but only because it zeroes a backward-turning wheel's acceleration;
    # the same state with that wheel at rest is not steady.
    x = [0.0, 0.0, fastest.steer_rad, fastest.speed_mps, 0.0, fastest.yaw_rate_radps, fastest.sideslip_rad,
         fastest.front_wheel_radps, 0.0]
    x[8] = fastest.speed_mps * np.cos(fastest.sideslip_rad) * (1.0 - fastest.rear_slip) / package_parameters(2).R_w
    u = [0.0, fastest.acceleration_mps2]
    steady = np.array(vehicle_dynamics_std(list(x), u, package_parameters(2)))[2:]
    assert np.max(np.abs(steady[[1, 3, 4, 5, 6]])) < 1e-5 and steady[5] == 0.0
    x[7] = 0.0
    assert np.max(np.abs(np.array(vehicle_dynamics_std(list(x), u, package_parameters(2)))[2:][[1, 3, 4, 5]])) > 1e-2
    why = describe_family(commonroad_drifts(2, 44.0, 0.4), frozen_front_wheel_drifts(2, 44.0, 0.4))
    assert "low-speed, high-wheelspin" in why and "front wheel turning backwards" in why


def test_the_controllers_model_drifts_where_the_car_does_on_both_circles():
    vehicle = fitted_model_vehicle(2, 44.0, 0.5, STD)
    car = commonroad_drifts(2, 44.0, 0.5)[0]
    left = drift_equilibrium(44.0, -0.5, pack_params(vehicle))
    right = drift_equilibrium(44.0, 0.5, pack_params(vehicle))
    assert abs(left.speed_mps - car.speed_mps) < 1e-6 and abs(left.steer_rad - car.steer_rad) < 1e-6
    assert abs(left.drive_force_n - vehicle.mass_kg * car.acceleration_mps2) < 1e-3
    assert right.speed_mps == left.speed_mps and right.steer_rad == -left.steer_rad
    # The offsets are the model's: the plant's own car never carries them.
    assert preset_config("commonroad_std").plant.vehicle(vehicle).steer_offset_rad == 0.0


def test_a_commonroad_config_is_one_key_and_refuses_what_cannot_drift():
    config = apply_overrides(EpisodeConfig(), {"plant.model": "commonroad_std", "scenario.sideslip_rad": 0.5})
    assert config == preset_config("commonroad_std") and drivable_reason(config) is None
    with pytest.raises(ConfigError, match="front-wheel drive"):
        apply_overrides(config, {"plant.commonroad_vehicle": 1})
    with pytest.raises(ConfigError, match="plant.tyre_c_scale shapes DriftLab's own plant"):
        apply_overrides(config, {"plant.tyre_c_scale": 1.1})
    # Parsing a sideslip outside the car's window does no physics; the drivability check and the fit refuse it.
    outside = apply_overrides(config, {"scenario.sideslip_rad": 0.4})
    assert "steers into the turn" in drivable_reason(outside)
    with pytest.raises(OutsideDriftWindowError, match="steers into the turn"):
        fitted(outside)
    with pytest.raises(ConfigError, match="plant.model must be one of"):
        apply_overrides(config, {"plant.model": "carsim"})


def test_parsing_a_commonroad_config_does_no_physics_and_its_fit_is_what_parsing_did_before(monkeypatch):
    """The model fit (0.3-0.8 s a new drift) happens when the config first runs, never in a parse: a job's config is
    stored with the fit still to do, and a runner fits it when it claims the job (tests/worker)."""
    document = {"plant.model": "commonroad_std", "scenario.sideslip_rad": 0.53, "scenario.left_radius_m": 41.0}
    import driftlab.core.commonroad.model_fit as model_fit

    calls = []
    fit = model_fit._fit
    monkeypatch.setattr(model_fit, "_fit", lambda *args: calls.append(args) or fit(*args))
    parsed = config_from_document(document)
    assert calls == [] and parsed.to_fit == {"vehicle", "plant.initial_rear_slip"}
    stored = config_to_dict(parsed)
    assert "vehicle" not in stored and "initial_rear_slip" not in stored["plant"]
    assert config_from_document(stored) == parsed and calls == []  # stored and read back: still to be fitted
    done = fitted(parsed)
    assert len(calls) == 1 and done.to_fit == frozenset()
    assert done.vehicle == fitted_model_vehicle(2, 41.0, 0.53, STD) and done.vehicle != EpisodeConfig().vehicle
    assert done.plant.initial_rear_slip == pytest.approx(commonroad_drifts(2, 41.0, 0.53)[0].rear_slip, abs=1e-4)
    assert config_from_document(config_to_dict(done)) == done  # fitted, it is stored in full and parsed as is
    # A model setting given on top of a config still to be fitted changes the fitted model (`--plant P --set
    # vehicle.mass_kg=...`), not Table I's.
    heavier = apply_overrides(parsed, {"vehicle.mass_kg": 1500.0})
    assert heavier.vehicle == replace(done.vehicle, mass_kg=1500.0) and heavier.to_fit == frozenset()
    # One episode of the parsed config is the episode of the fitted one, bit for bit.
    short = {"scenario.max_time_s": 3.0}
    a, b = run_episode(Theta(), apply_overrides(parsed, short)), run_episode(Theta(), apply_overrides(done, short))
    assert a.J == b.J and (a.trajectory == b.trajectory).all()


def test_without_the_package_the_error_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "vehiclemodels.vehicle_parameters", None)
    with pytest.raises(ConfigError, match=r"driftlab\[commonroad\]"):
        _vehiclemodels()


def test_an_std_episode_is_a_pure_function_of_its_arguments():
    config = preset_config("commonroad_std")
    first, again = (run_episode(Theta(), config, seed=4) for _ in range(2))
    assert first.J == again.J and np.array_equal(first.trajectory, again.trajectory)
    assert first.trajectory[0, 4] == pytest.approx(commonroad_drifts(2, 44.0, 0.5)[0].speed_mps, abs=0.5)


def test_the_plant_key_brings_the_cars_controller_and_switching_back_restores_the_default():
    config = preset_config("commonroad_std")
    assert config.mpc == std_weights() and config.scenario.sideslip_rad == 0.5
    back = apply_overrides(config, {"plant.model": "driftlab", "scenario.sideslip_rad": 0.4})
    assert back == EpisodeConfig()
    kept = apply_overrides(EpisodeConfig(), {"plant.model": "commonroad_std", "scenario.sideslip_rad": 0.5,
                                             "mpc.q_sideslip": 500.0})
    assert kept.mpc.q_sideslip == 500.0 and kept.mpc.q_steer == MpcConfig().q_steer  # mpc keys given: kept


@pytest.mark.e2e
@pytest.mark.parametrize(("beta", "expected"), [("-0.5", None), ("-0.4", "steers into the turn")])
def test_driftlab_equilibrium_prints_the_plants_drift_family(beta, expected):
    out = subprocess.run([sys.executable, "-m", "driftlab.cli", "equilibrium", "--plant", "commonroad_std",
                          "--radius", "44", "--beta", beta], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    plant = json.loads(out.stdout)["plant"]
    if expected is None:
        assert plant["countersteer"] and abs(plant["V"] - 20.50) <= 0.05 and abs(plant["delta"] + 0.264) <= 0.005
        assert "error" not in plant and plant["rear_slip"] < -0.4
        low, high = plant["countersteer_window_rad"]  # where the scenario's drift can be held at this radius
        assert 0.4 < low <= 0.45 and high >= 0.6
    else:
        assert not plant["countersteer"] and expected in plant["error"] and plant["delta"] > 0


def test_the_compiled_mb_equals_the_package_on_random_states():
    from vehiclemodels.init_mb import init_mb
    from vehiclemodels.vehicle_dynamics_mb import vehicle_dynamics_mb

    from driftlab.core.commonroad.mb import mb_derivatives, pack_mb

    p, cp = package_parameters(2), pack_mb(2)
    rng = np.random.default_rng(5)
    spread = np.r_[np.zeros(6), 0.02, 0.1, 0.01, 0.1, 0.3, 0.01, 0.05, 0.02, 0.1, 0.3, 0.005, 0.05, 0.02, 0.1, 0.3,
                   0.005, 0.05, 2.0, 2.0, 2.0, 2.0, 0.001, 0.001]
    for i in range(300):
        speed = rng.uniform(0.0, 0.09) if i % 10 == 0 else rng.uniform(3.0, 30.0)
        x = np.array(init_mb([0.0, 0.0, rng.uniform(-0.5, 0.5), speed, 0.3, rng.uniform(-0.1, 0.1) * speed,
                              rng.uniform(-0.8, 0.8)], p)) + rng.normal(0.0, 1.0, 29) * spread
        u = [rng.uniform(-2.0, 2.0), rng.uniform(-8.0, 8.0)]
        expected = np.array(vehicle_dynamics_mb(list(x), u, p))
        # Equal to the last bit but for a rounding here and there (numba's and CPython's x ** 2).
        np.testing.assert_allclose(mb_derivatives(x.copy(), np.array(u), cp), expected, rtol=1e-12, atol=1e-9)


def test_the_multibody_cars_steady_drift_with_a_locked_differential():
    from driftlab.core.commonroad.mb_equilibrium import mb_main_drift, mb_steady_state

    left = mb_main_drift(2, 44.0, 0.5)
    right = mb_main_drift(2, 44.0, 0.5, right=True)
    assert left.countersteer and right.countersteer and left.steer_rad < 0 < right.steer_rad
    # MB's own drift, not STD's: more countersteer and less drive with four wheels and a rolling body.
    std = commonroad_drifts(2, 44.0, 0.5)[0]
    assert abs(left.speed_mps - std.speed_mps) < 0.5 and left.steer_rad < std.steer_rad - 0.1
    assert left.rear_slip < 0 and left.acceleration_mps2 < std.acceleration_mps2
    assert 50.0 < left.front_wheel_radps < 70.0  # rolling (V cos(beta) / wheel radius ~ 59 rad/s), not frozen
    # The drift is a steady state of the package's own equations, the rear wheels on one shaft.
    from vehiclemodels.vehicle_dynamics_mb import vehicle_dynamics_mb

    _, state, accel = mb_steady_state(2, 44.0, 0.5)
    f = np.array(vehicle_dynamics_mb(list(state), [0.0, accel], package_parameters(2)))
    steady = [3, 5, 7, 9, 10, 12, 14, 15, 17, 19, 20, 22, 23, 24, 27, 28]
    assert np.max(np.abs(f[steady])) < 1e-6 and abs(f[25] + f[26]) < 1e-6
    assert f[4] == pytest.approx(left.yaw_rate_radps) and np.hypot(f[0], f[1]) == pytest.approx(left.speed_mps)


def test_the_multibody_drift_family_is_found_at_every_sideslip_where_it_is_continuous():
    """Started from STD's drift, the solve misses MB's drift at 0.46, 0.48 and 0.55 rad; followed from 0.5 rad,
    each is found, between its neighbours, and a steady state of the package's equations."""
    from vehiclemodels.vehicle_dynamics_mb import vehicle_dynamics_mb

    from driftlab.core.commonroad.mb_equilibrium import mb_main_drift, mb_steady_state

    family = [mb_main_drift(2, 44.0, beta) for beta in (0.3, 0.44, 0.46, 0.48, 0.5, 0.52, 0.55, 0.58, 0.7)]
    assert all(drift is not None and drift.countersteer for drift in family)
    speeds = [drift.speed_mps for drift in family]
    steers = [drift.steer_rad for drift in family]
    assert all(np.diff(speeds) < 0) and all(np.diff(steers) < 0)  # faster and less countersteer at less sideslip
    _, state, accel = mb_steady_state(2, 44.0, 0.55)
    f = np.array(vehicle_dynamics_mb(list(state), [0.0, accel], package_parameters(2)))
    assert np.max(np.abs(f[[3, 5, 10, 15, 20]])) < 1e-6


def _published(config: EpisodeConfig, **more) -> EpisodeConfig:
    """MB as the package publishes it: no wheel lift-off."""
    return apply_overrides(config, {"plant.wheel_liftoff": False, **more})


def _published_mb_without_the_validity_rule(max_time_s: float) -> EpisodeConfig:
    """The loop's mechanics past the first second: the published MB, its episodes not ended as invalid."""
    return _published(preset_config("commonroad_mb"),
                      **{"failure.invalid_ends_episode": False, "scenario.max_time_s": max_time_s})


def test_an_mb_episode_runs_in_the_same_loop_and_is_pure():
    config = _published_mb_without_the_validity_rule(5.0)
    first, again = (run_episode(Theta(), config, seed=1) for _ in range(2))
    assert first.trajectory[-1, 0] > 4.9  # through the first flick's approach, not stopped early
    assert first.J == again.J and np.array_equal(first.trajectory, again.trajectory)
    assert first.trajectory[0, 4] == pytest.approx(20.39, abs=0.2)  # it starts in MB's own drift


def test_mb_stepped_in_its_compiled_loop_is_mb_stepped_from_python_bit_for_bit(monkeypatch):
    from driftlab.core.commonroad.mb_plant import CommonRoadMbPlant

    config = _published_mb_without_the_validity_rule(4.0)
    compiled = run_episode(Theta(), config, seed=2)
    monkeypatch.setattr(CommonRoadMbPlant, "run_loop", None)  # the kernel returns for each plant step
    from_python = run_episode(Theta(), config, seed=2)
    assert len(compiled.trajectory) > 70
    assert np.array_equal(compiled.trajectory, from_python.trajectory) and compiled.J == from_python.J
    assert compiled.metrics.plant_validity == from_python.metrics.plant_validity


def test_mbs_substep_integrates_a_control_step_as_a_fine_one_does(monkeypatch):
    """The preset's RK4 substep against a 0.1 ms one, over the control steps of an episode: the fastest mode (a
    wheel's speed, ~ -300 1/s) stays inside RK4's stability bound and the step's error is far below the noise."""
    from driftlab.core.commonroad import mb_plant as crp

    config = _published_mb_without_the_validity_rule(3.0)
    steps = []
    record = crp.mb_recorded_step

    def recording(state, steer, drive, dt, substep_s, p, act, lowest, validity):
        steps.append((state.copy(), steer, drive, dt, p, act))
        return record(state, steer, drive, dt, substep_s, p, act, lowest, validity)

    monkeypatch.setattr(crp, "mb_recorded_step", recording)
    monkeypatch.setattr(crp.CommonRoadMbPlant, "run_loop", None)  # each step through Python, to be recorded
    run_episode(Theta(), config, seed=3)
    assert config.plant.substep_s == 0.003 and len(steps) > 50
    for state, steer, drive, dt, p, act in steps[::4]:
        fine = crp.mb_plant_step(state, steer, drive, dt, 1e-4, p, act)
        preset = crp.mb_plant_step(state, steer, drive, dt, config.plant.substep_s, p, act)
        assert np.hypot(*(preset[:2] - fine[:2])) < 2e-5  # position [m]
        assert abs(preset[4] - fine[4]) < 2e-5 and abs(preset[5] - fine[5]) < 1e-3  # sideslip, yaw rate


def test_the_mb_model_answers_the_steering_as_the_car_does_and_std_keeps_its_read_off_grip():
    from driftlab.core.commonroad.mb_equilibrium import mb_main_drift
    from driftlab.core.commonroad.steering_gain import car_yaw_response, model_yaw_response

    drift = mb_main_drift(2, 44.0, 0.5)
    car, steering, _ = car_yaw_response(_stepper(MB), drift, 44.0)
    fitted = fitted_model_vehicle(2, 44.0, 0.5, MB)
    right = mb_main_drift(2, 44.0, 0.5, right=True)
    read_off = _placed_at_drift(replace(fitted, front_grip_scale=1.0), 44.0, 0.5, drift, right)
    assert car > 3 * model_yaw_response(read_off, drift, steering)  # the mismatch the fit removes
    assert model_yaw_response(fitted, drift, steering) == pytest.approx(car, rel=1e-3)
    # The front axle's grip as the car answers: more than the tyres' read-off (the fit's whole point), less than
    # the published model's pulling inner tyre gave it (1.2-1.7): with lift-off that wheel is in the air here.
    assert 1.1 < fitted.front_grip_scale < 1.7
    # The fitted model still drifts where the car does.
    eq = drift_equilibrium(44.0, -0.5, pack_params(fitted))
    assert eq.speed_mps == pytest.approx(drift.speed_mps, abs=1e-6) and eq.steer_rad == pytest.approx(
        drift.steer_rad, abs=1e-6)
    assert fitted_model_vehicle(2, 44.0, 0.5, STD).front_grip_scale == 1.0  # STD's front axle is saturated


def test_the_mb_model_answers_more_drive_with_more_yaw_rate_as_the_car_does():
    """MB's rear wheels spin up under more drive and its rear slides out: its yaw rate rises. The paper's model
    (drive and rear lateral force independent) answers with less; the model with the rear friction circle with
    more, as the car does, so the MPC no longer pushes the drive the wrong way to hold the sideslip."""
    from driftlab.core.commonroad.mb_equilibrium import mb_main_drift
    from driftlab.core.commonroad.steering_gain import car_yaw_response, model_yaw_response

    drift = mb_main_drift(2, 44.0, 0.5)
    car, steering, drive = car_yaw_response(_stepper(MB), drift, 44.0, steer_step_rad=0.0,
                                            drive_step_n=500.0)
    fitted = fitted_model_vehicle(2, 44.0, 0.5, MB)
    assert fitted.rear_friction_circle and not fitted_model_vehicle(2, 44.0, 0.5, STD).rear_friction_circle
    paper_coupling = replace(fitted, rear_friction_circle=False)
    assert car > 0.02  # rad/s, mean over 0.1..0.3 s
    assert model_yaw_response(fitted, drift, steering, drive) > 0.5 * car
    assert model_yaw_response(paper_coupling, drift, steering, drive) < 0.0


def test_an_mb_plant_starts_steady_in_its_own_drift():
    """With no variation the episode's first steps hold MB's drift: every wheel at its own slip, the body rolled (the
    published model's: with lift-off its inner front wheel, pulling here, lifts)."""
    from driftlab.core.commonroad.mb_equilibrium import mb_main_drift
    from driftlab.core.plant import DRIVE, SIDESLIP, SPEED, STEER, YAW_RATE

    drift = mb_main_drift(2, 44.0, 0.5)
    plant = make_plant(replace(MB.preset(2), wheel_liftoff=False),
                       fitted_model_vehicle(2, 44.0, 0.5, MB))
    plant.start_in_drift_of(44.0, 0.5)
    loop = np.zeros(8)
    loop[SPEED], loop[SIDESLIP], loop[YAW_RATE] = drift.speed_mps, drift.sideslip_rad, drift.yaw_rate_radps
    loop[STEER], loop[DRIVE] = drift.steer_rad, drift.drive_n
    state = plant.start_state(loop)
    for _ in range(10):
        state = plant.step(state, drift.steer_rad, drift.drive_n, 0.05)
    assert abs(state[SPEED] - drift.speed_mps) < 1e-3 and abs(state[YAW_RATE] - drift.yaw_rate_radps) < 1e-3
    assert abs(state[SIDESLIP] - drift.sideslip_rad) < 1e-4


def test_a_plant_stepped_in_python_runs_the_same_loop_bit_for_bit():
    """The package's own STD functions, stepped in Python (a registered plant), against the compiled port: the same
    episode bit for bit; DriftLab's own plant registered as a Python plant against its compiled step: the same."""
    from dataclasses import replace

    from driftlab.core.plant import PLANT_EXTERNAL, Plant
    from driftlab.core.plants import register_plant

    config = apply_overrides(preset_config("commonroad_std"), {"scenario.max_time_s": 3.0})
    reference = replace(config, plant=replace(config.plant, model="commonroad_std_reference"))
    compiled, python = run_episode(Theta(), config, seed=2), run_episode(Theta(), reference, seed=2)
    assert len(compiled.trajectory) > 50 and np.array_equal(compiled.trajectory, python.trajectory)

    class PythonStepped(Plant):
        kind = PLANT_EXTERNAL

    register_plant("driftlab_in_python", lambda plant: PythonStepped(replace(plant, model="driftlab"),
                                                                     EpisodeConfig().vehicle))
    default = EpisodeConfig()
    mine = replace(default, plant=replace(default.plant, model="driftlab_in_python"))
    a, b = run_episode(Theta(), default, seed=5), run_episode(Theta(), mine, seed=5)  # a whole figure 8
    assert a.completed and a.J == b.J and np.array_equal(a.trajectory, b.trajectory)
    with pytest.raises(ConfigError, match="or a registered plant"):
        apply_overrides(default, {"plant.model": "not_registered"})


def test_a_model_with_matched_drive_coupling_answers_the_drive_as_the_car_does():
    """STD's car, like MB's, answers more drive with more yaw rate (its rear slides further); the paper's model
    does not answer and the whole friction circle answers twice as strongly: the coupling is matched to the car."""
    from driftlab.core.commonroad.steering_gain import DRIVE_STEP_N, car_yaw_response, model_yaw_response

    drift = commonroad_drifts(2, 44.0, 0.5)[0]
    car, steering, drive = car_yaw_response(_stepper(STD), drift, 44.0, steer_step_rad=0.0,
                                            drive_step_n=DRIVE_STEP_N)
    paper = fitted_model_vehicle(2, 44.0, 0.5, STD)
    matched = fitted_model_vehicle(2, 44.0, 0.5, STD, drive_coupling=True)
    assert car > 0.015 and abs(model_yaw_response(paper, drift, steering, drive)) < 0.002
    assert matched.rear_friction_circle and 0.5 < matched.rear_coupling < 0.95
    assert model_yaw_response(matched, drift, steering, drive) == pytest.approx(car, abs=2e-4)


def test_the_published_mbs_episode_ends_invalid_once_a_wheel_has_pulled_the_road_too_long():
    """MB does not clamp a tyre's normal load at zero: in the BMW's 0.5 rad drift its inner front wheel pulls the
    road within 0.2 s. The episode reports it (each wheel's lowest load; its loads at the start sum to the car's
    weight) and ends as invalid once that lasted past failure.max_invalid_s, its J a failure's; without the rule
    it runs on, as stored jobs of earlier releases ran."""
    from driftlab.core.commonroad.mb import mb_wheel_loads
    from driftlab.core.commonroad.parameters import package_parameters
    from driftlab.core.episode import failure_penalty

    config = _published(preset_config("commonroad_mb"), **{"scenario.max_time_s": 2.0})
    plant = make_plant(config.plant, config.vehicle)
    loop = np.zeros(8)
    loop[4] = 20.0
    state = plant.start_state(loop)
    assert mb_wheel_loads(state[8:8 + 29], plant.params).sum() == pytest.approx(package_parameters(2).m * 9.81,
                                                                                 rel=0.02)
    result = run_episode(Theta(), config, seed=0)
    validity = result.metrics.plant_validity
    assert result.status == "invalid"
    assert result.J == failure_penalty(result.metrics.completed_fraction)
    limit_s, step_s = config.failure.max_invalid_s, config.mpc.dt_s
    assert limit_s < validity["invalid_s"] <= limit_s + step_s + 1e-9
    assert validity["invalid_s"] == validity["negative_wheel_load_s"]  # the published model: any wheel pulling
    lowest = validity["min_wheel_load_n"]
    assert set(lowest) == {"lf", "rf", "lr", "rr"} and min(lowest.values()) < 0.0
    assert result.metrics.duration_s == pytest.approx(validity["first_negative_wheel_load_s"] + validity["invalid_s"]
                                                      - step_s, abs=step_s + 1e-9)
    ruleless = run_episode(Theta(), apply_overrides(config, {"failure.invalid_ends_episode": False}), seed=0)
    assert ruleless.status != "invalid" and ruleless.metrics.duration_s > result.metrics.duration_s
    assert ruleless.metrics.plant_validity["negative_wheel_load_s"] > limit_s
    assert run_episode(Theta(), apply_overrides(preset_config("commonroad_std"),
                                                {"scenario.max_time_s": 1.0}), seed=0).metrics.plant_validity is None


def test_a_lifted_wheel_carries_no_force_and_a_loaded_one_is_the_published_models():
    """With wheel lift-off, a state whose four tyres are on the road has the published model's derivatives bit for
    bit; where the inner front tyre's spring would pull (its wheel in the air), the published model's drift is no
    drift any more: its pulling tyre was part of what held it."""
    from driftlab.core.commonroad.mb import mb_derivatives, mb_wheel_loads, pack_mb
    from driftlab.core.commonroad.mb_equilibrium import mb_steady_state

    published, lifting = pack_mb(2), pack_mb(2, wheel_liftoff=True)
    _, on_road, accel = mb_steady_state(2, 44.0, 0.8)
    assert mb_wheel_loads(on_road, published).min() > 0.0
    u = np.array([0.0, accel])
    assert np.array_equal(mb_derivatives(on_road, u, lifting), mb_derivatives(on_road, u, published))
    _, pulling, accel = mb_steady_state(2, 44.0, 0.5)
    loads = mb_wheel_loads(pulling, published)
    assert loads[1] < 0.0 < min(loads[0], loads[2], loads[3])  # the package's rf: the inner front in a left drift
    u = np.array([0.0, accel])
    steady, lifted = mb_derivatives(pulling, u, published), mb_derivatives(pulling, u, lifting)
    body = [3, 5, 10]  # longitudinal, yaw and lateral accelerations
    assert np.abs(steady[body]).max() < 1e-6  # the published model's drift: held by the pulling tyre
    assert np.abs(lifted[body]).max() > 0.1  # without it the car is not in equilibrium there
    assert lifted[24] == 0.0  # the undriven wheel in the air: nothing turns it


def test_mb_lifts_its_wheels_by_default_and_the_published_model_is_one_setting_away():
    mb = preset_config("commonroad_mb")
    assert mb.plant.wheel_liftoff and mb.failure.invalid_ends_episode
    assert not _published(mb).plant.wheel_liftoff
    assert not preset_config("commonroad_std").plant.wheel_liftoff
    with pytest.raises(ConfigError, match=r"plant\.wheel_liftoff applies to a plant with wheel loads"):
        apply_overrides(EpisodeConfig(), {"plant.wheel_liftoff": True})


def test_with_lift_off_an_episode_reports_time_off_the_road_and_on_two_wheels():
    """MB's BMW reaches ~0.96 g in its 0.5 rad, 44 m drift, 94% of the lateral acceleration at which its steady
    states' inner loads sum to zero: its inner front wheel lifts at once. The record keeps the time any wheel was off
    the road apart from the time two wheels of one side were, which alone is outside the model with lift-off."""
    result = run_episode(Theta(), apply_overrides(preset_config("commonroad_mb"),
                                                  {"scenario.max_time_s": 3.0}), seed=0)
    validity = result.metrics.plant_validity
    assert validity["wheel_liftoff"] is True
    assert validity["negative_wheel_load_s"] >= validity["one_side_off_s"] == validity["invalid_s"]
    assert validity["negative_wheel_load_s"] > 0.0
    assert (result.status == "invalid") == (validity["invalid_s"] > 0.2)


def test_sideslip_window_finds_a_runs_edges_to_the_grid():
    assert sideslip_window(lambda b: 0.42 <= b + 1e-9 and b <= 0.57 + 1e-9) == (0.42, 0.57)
    assert sideslip_window(lambda b: b >= 0.56 - 1e-9) == (0.56, 0.8)
    assert sideslip_window(lambda b: False) is None


def test_a_refused_sideslip_names_where_the_car_and_its_model_both_drift():
    """The window the refusal names, checked point by point: the car's main drift countersteers both ways at its
    edges and not one step outside. The model read off the car's tyres drifts up to 0.57 rad; above, its front grip
    is raised until it does, so the car's own window is the job's."""
    config = fitted(preset_config("commonroad_std"))
    with pytest.raises(ConfigError) as refused:
        fitted(apply_overrides(config, {"scenario.sideslip_rad": 0.3}))
    found = re.search(r"needs a scenario.sideslip_rad in (\d\.\d\d)-(\d\.\d\d) rad", str(refused.value))
    assert found and refused.value.field == "scenario.sideslip_rad", str(refused.value)
    low, high = float(found[1]), float(found[2])

    def car_countersteers(beta, right):
        family = commonroad_drifts(2, 44.0, beta, right=right)
        return bool(family and family[0].countersteer)

    assert car_countersteers(low, False) and car_countersteers(low, True)
    assert not (car_countersteers(round(low - 0.01, 2), False) and car_countersteers(round(low - 0.01, 2), True))
    assert high == 0.8 and car_countersteers(high, False) and car_countersteers(high, True)  # the end of the scan
    model = pack_params(commonroad_model_vehicle(2))
    drift_equilibrium(44.0, -0.57, model)  # raises if the model has no drift there
    with pytest.raises(NoEquilibriumError):
        drift_equilibrium(44.0, -0.58, model)
    above = fitted(apply_overrides(config, {"scenario.sideslip_rad": 0.6}))
    assert config.vehicle.front_grip_scale == 1.0 and 1.0 < above.vehicle.front_grip_scale <= 1.1
    drift_equilibrium(44.0, -0.6, pack_params(above.vehicle))


def test_an_std_car_starts_its_rear_wheel_at_the_slip_of_its_own_drift():
    """A start at another rear slip is a step of the rear force: the VW Vanagon drifts at 0.62 rad with its rear
    wheel at slip -0.93; started at the old fixed -0.5 it grips up before its first flick, started in its drift it
    holds the drift to the trigger."""
    vanagon = {"plant.model": "commonroad_std", "plant.commonroad_vehicle": 3, "scenario.sideslip_rad": 0.62}
    config = fitted(apply_overrides(EpisodeConfig(), vanagon))
    main = commonroad_drifts(3, 44.0, 0.62)[0]
    assert config.plant.initial_rear_slip == pytest.approx(main.rear_slip, abs=1e-4) and main.rear_slip < -0.9
    held = run_episode(Theta(), config, seed=1)
    assert held.metrics.trigger_times_s, held.status
    old = run_episode(Theta(), apply_overrides(EpisodeConfig(), {**vanagon, "plant.initial_rear_slip": -0.5}), seed=1)
    assert old.status == "gripped_up" and not old.metrics.trigger_times_s
    # A config that names its start (as every stored job's does) keeps it when it is loaded again.
    assert config_from_document(config_to_dict(old_config := apply_overrides(
        EpisodeConfig(), {**vanagon, "plant.initial_rear_slip": -0.5}))).plant == old_config.plant
    assert fitted(preset_config("commonroad_std")).plant.initial_rear_slip == pytest.approx(
        commonroad_drifts(2, 44.0, 0.5)[0].rear_slip, abs=1e-4)
