"""Offset-free drift control: the disturbance estimate, its freezing around flicks, and a reference that moves
to the plant's own drift (checked against the plant's equilibrium, solved independently)."""

import numpy as np
import pytest

from driftlab.core.config import Theta
from driftlab.core.configure import apply_overrides, preset_config
from driftlab.core.controller import hold_estimate
from driftlab.core.episode import run_episode
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.mpc import MpcConfig, update_estimate
from driftlab.core.planner import Phase
from driftlab.core.vehicle import pack_params

LIMIT = np.array([5.0, 2.0, 5.0])


def _estimator(gain, dt, start_gain):
    """update_estimate as the closed loop drives it: its arrays, updated in place."""
    value, count = np.zeros(3), np.zeros(1, dtype=np.int64)
    return lambda innovation: update_estimate(value, count, innovation, gain, start_gain, dt, LIMIT).copy()


def test_estimate_starts_as_a_capped_running_mean_then_filters_at_the_gain():
    dt = 0.05
    update = _estimator(0.05, dt, start_gain=0.2)
    measured = np.array([0.3, -0.1, 0.2])
    expected = np.zeros(3)
    for n in range(1, 40):
        gain = max(0.05, min(0.2, 1.0 / n))
        expected = expected + gain * (measured - expected)
        np.testing.assert_allclose(update(measured * dt), expected, rtol=1e-12)
    uncapped = _estimator(0.0001, dt, start_gain=1.0)
    samples = [np.array([v, 0.0, -v]) for v in (0.1, 0.4, -0.2, 0.3)]
    for sample in samples:
        value = uncapped(sample * dt)
    np.testing.assert_allclose(value, np.mean(samples, axis=0), rtol=1e-12)  # n = 4 <= 1 / gain: the mean


def test_estimate_is_held_through_a_flick_and_its_aftermath():
    mpc = MpcConfig(disturbance_gain=0.1, estimator_hold_s=0.5)
    hold_steps = int(round(mpc.estimator_hold_s / mpc.dt_s))
    frozen, left = hold_estimate(False, 0, hold_steps)
    assert not frozen
    frozen, left = hold_estimate(True, left, hold_steps)  # the inertia phase
    assert frozen
    held = []
    for _ in range(12):
        frozen, left = hold_estimate(False, left, hold_steps)
        held.append(frozen)
    assert held == [True] * 9 + [False] * 3  # 0.5 s at 0.05 s: the first 9 steps after the flick, then free


@pytest.mark.parametrize("friction", [0.9, 1.1])
def test_reference_moves_to_the_plants_own_drift(friction):
    """On the nominal car with other friction, the drift at R 44, beta 0.4 is slower or faster than the
    model's: the reference speed settles at the plant's equilibrium in the first sustained drift, and the car
    drives nearer the plant's drift than the model's (it trades some speed error for the path, not settled)."""
    config = apply_overrides(preset_config(plant="nominal"), {"plant.friction_scale": friction})
    plant_eq = drift_equilibrium(44.0, -0.4, config.plant.packed_params(config.vehicle))
    model_eq = drift_equilibrium(44.0, -0.4, pack_params(config.vehicle))
    assert abs(plant_eq.speed_mps - model_eq.speed_mps) > 0.9  # a real shift, not a rounding
    r = run_episode(Theta(), config)
    assert r.status == "completed"
    t, phase = r.column("t_s"), r.column("phase")
    late_first_drift = (t > 4.0) & (phase == Phase.LEFT_DRIFT)
    assert late_first_drift.sum() > 10
    assert np.all(np.abs(r.column("V_ref_mps")[late_first_drift] - plant_eq.speed_mps) < 0.1)
    shift = abs(plant_eq.speed_mps - model_eq.speed_mps)
    assert np.all(np.abs(r.column("V_mps")[late_first_drift] - plant_eq.speed_mps) < 0.5 * shift)
    assert np.all(np.abs(r.column("beta_rad")[late_first_drift] - plant_eq.sideslip_rad) < 0.02)


def test_the_paper_controller_has_no_offset_free_parts():
    paper = MpcConfig.paper()
    assert paper.disturbance_gain == 0.0 and not paper.feedback_in_model and not paper.path_states


def test_unequal_radii_drift_each_circle_at_its_own_equilibrium():
    """The paper's future work: a 30 m left circle and a 44 m right one, each with its own reference drift, and
    the reference speed moved to the next circle's before each flick (scenario.speed_change_accel_mps2)."""
    config = apply_overrides(preset_config(plant="nominal"), {"scenario.left_radius_m": 30.0,
                                                                       "scenario.right_radius_m": 44.0})
    r = run_episode(Theta(), config)
    assert r.status == "completed"
    params = pack_params(config.vehicle)
    t, phase = r.column("t_s"), r.column("phase")
    x, y, speed_ref = r.column("x_m"), r.column("y_m"), r.column("V_ref_mps")
    left_eq, right_eq = drift_equilibrium(30.0, -0.4, params), drift_equilibrium(44.0, -0.4, params)
    for drift, radius, centre_y, eq, next_eq in ((Phase.LEFT_DRIFT, 30.0, 30.0, left_eq, right_eq),
                                                 (Phase.RIGHT_DRIFT, 44.0, -44.0, right_eq, left_eq)):
        rows = np.flatnonzero(phase == drift)
        middle = rows[len(rows) // 3: len(rows) // 2]
        assert np.all(np.abs(speed_ref[middle] - eq.speed_mps) < 0.05)
        assert np.all(np.abs(np.abs(r.column("r_ref_radps")[middle]) - eq.yaw_rate_radps) < 0.005)
        # at the trigger the reference speed has gone most of the way to the next circle's drift speed
        moved = (speed_ref[rows[-1]] - eq.speed_mps) / (next_eq.speed_mps - eq.speed_mps)
        assert 0.8 < moved <= 1.0
        settled = rows[t[rows] > t[rows][0] + 2.0]  # past the flick's aftermath
        off_path = np.abs(np.hypot(x[settled], y[settled] - centre_y) - radius)
        assert np.all(off_path < 0.5)  # the speed changed before the flick: no running wide after it


def test_unequal_radii_scale_dv_by_each_circles_drift_speed():
    """dV is a correction at the left circle's drift speed; the right circle's moves by the same share."""
    config = apply_overrides(preset_config(plant="nominal"), {"scenario.left_radius_m": 30.0,
                                                                       "scenario.right_radius_m": 44.0})
    r = run_episode(Theta(dV=0.5), config)
    assert r.status == "completed"
    params = pack_params(config.vehicle)
    left_eq, right_eq = drift_equilibrium(30.0, -0.4, params), drift_equilibrium(44.0, -0.4, params)
    phase, speed_ref = r.column("phase"), r.column("V_ref_mps")
    for drift, eq, offset in ((Phase.LEFT_DRIFT, left_eq, 0.5),
                              (Phase.RIGHT_DRIFT, right_eq, 0.5 * right_eq.speed_mps / left_eq.speed_mps)):
        rows = np.flatnonzero(phase == drift)
        middle = rows[len(rows) // 3: len(rows) // 2]
        np.testing.assert_allclose(speed_ref[middle], eq.speed_mps + offset, atol=0.03)
