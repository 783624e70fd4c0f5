"""The plant: nominal equals the 3-state model; RK4 step accuracy; actuator behaviour."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.plant import SIDESLIP, SPEED, STEER, YAW_RATE, Plant, PlantConfig
from driftlab.core.vehicle import VehicleParams, drift_derivatives_vec, pack_params

VEHICLE = VehicleParams()
EQ = drift_equilibrium(44.0, -0.4, pack_params(VEHICLE))


def _start(eq=EQ, offset=(0.3, 0.03, -0.05)):
    s = np.zeros(8)
    s[SPEED:YAW_RATE + 1] = eq.state + np.array(offset)
    s[STEER], s[STEER + 1] = eq.inputs
    return s


def test_nominal_plant_equals_the_three_state_model():
    plant = Plant(PlantConfig.nominal(), VEHICLE)
    s = _start()
    for _ in range(20):  # 1 s of held inputs
        s = plant.step(s, EQ.steer_rad, EQ.drive_force_n, 0.05)
    p = pack_params(VEHICLE)
    ref = solve_ivp(lambda t, x: drift_derivatives_vec(x, EQ.inputs, p), (0.0, 1.0), _start()[SPEED:YAW_RATE + 1],
                    rtol=1e-11, atol=1e-11, method="DOP853")
    np.testing.assert_allclose(s[SPEED:YAW_RATE + 1], ref.y[:, -1], atol=1e-7)


def test_default_plant_rk4_step_against_fine_reference():
    config = PlantConfig()
    coarse, fine = Plant(config, VEHICLE), Plant(PlantConfig(substep_s=0.0005), VEHICLE)
    a = b = _start()
    for k in range(40):
        steer = EQ.steer_rad + 0.1 * np.sin(k / 3.0)
        a = coarse.step(a, steer, EQ.drive_force_n, 0.05)
        b = fine.step(b, steer, EQ.drive_force_n, 0.05)
    assert np.max(np.abs(a[SPEED:YAW_RATE + 1] - b[SPEED:YAW_RATE + 1])) < 1e-4


def test_plant_sits_still_at_its_own_equilibrium():
    config = PlantConfig()
    plant = Plant(config, VEHICLE)
    own = drift_equilibrium(44.0, -0.4, plant.params)
    s = _start(own, offset=(0.0, 0.0, 0.0))
    for _ in range(10):
        s = plant.step(s, own.steer_rad, own.drive_force_n, 0.05)
    np.testing.assert_allclose(s[SPEED:YAW_RATE + 1], own.state, atol=1e-6)


def test_steering_actuator_lag_and_rate_limit():
    config = PlantConfig(steer_lag_s=0.05, steer_rate_radps=2.0)
    plant = Plant(config, VEHICLE)
    s = plant.step(_start(), EQ.steer_rad + 0.5, EQ.drive_force_n, 0.05)
    moved = s[STEER] - EQ.steer_rad
    assert 0.0 < moved <= 2.0 * 0.05 + 1e-9  # rate limited: at most 0.1 rad in 50 ms


def test_plant_config_names_bad_field():
    from driftlab.core.errors import ConfigError

    with pytest.raises(ConfigError, match="plant.cg_height_m"):
        PlantConfig(cg_height_m=-1.0)
    assert SIDESLIP == 4
