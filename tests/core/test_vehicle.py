"""The drift model against the paper's Table I and docs/reference.md (The car)."""

import numpy as np
import pytest

from driftlab.core.equilibrium import drift_equilibrium, eigenvalues, jacobians
from driftlab.core.errors import ConfigError, NoEquilibriumError
from driftlab.core.plant import PlantConfig
from driftlab.core.vehicle import VehicleParams, drift_derivatives_vec, pack_params, tyre_forces

MODEL = pack_params(VehicleParams())


@pytest.fixture(scope="module")
def left_eq():
    return drift_equilibrium(44.0, -0.4, MODEL)


def test_table_one_reproduced_within_half_percent(left_eq):
    table_one = {"speed_mps": 19.1, "yaw_rate_radps": 0.434, "steer_rad": -0.270, "drive_force_n": 4324.0}
    for name, expected in table_one.items():
        assert getattr(left_eq, name) == pytest.approx(expected, rel=5e-3), name
    assert left_eq.sideslip_rad == -0.4


def test_equilibrium_is_steady_to_solver_tolerance(left_eq):
    assert np.max(np.abs(drift_derivatives_vec(left_eq.state, left_eq.inputs, MODEL))) < 1e-9


def test_table_one_force_ratios(left_eq):
    fyf, fyr, _ = tyre_forces(*left_eq.state, *left_eq.inputs, MODEL)
    fzf, fzr = VehicleParams().static_axle_loads_n()
    assert abs(fyf) / fzf == pytest.approx(0.808, abs=2e-3)
    assert abs(fyr) / fzr == pytest.approx(0.778, abs=2e-3)


def test_right_hand_drift_is_exact_mirror(left_eq):
    right = drift_equilibrium(44.0, 0.4, MODEL)
    assert right.speed_mps == pytest.approx(left_eq.speed_mps, abs=1e-9)
    assert right.drive_force_n == pytest.approx(left_eq.drive_force_n, abs=1e-6)
    assert right.yaw_rate_radps == pytest.approx(-left_eq.yaw_rate_radps, abs=1e-12)
    assert right.steer_rad == pytest.approx(-left_eq.steer_rad, abs=1e-12)
    # The model itself is mirror symmetric: derivatives flip sign in beta and r.
    mirrored = drift_derivatives_vec(np.array([19.0, 0.3, -0.5]), np.array([0.2, 3000.0]), MODEL)
    original = drift_derivatives_vec(np.array([19.0, -0.3, 0.5]), np.array([-0.2, 3000.0]), MODEL)
    np.testing.assert_allclose(mirrored, original * np.array([1.0, -1.0, -1.0]), atol=1e-12)


def test_equilibrium_is_a_saddle_with_reference_eigenvalues(left_eq):
    eig = np.sort(eigenvalues(left_eq, MODEL).real)
    np.testing.assert_allclose(eig, [-3.529, 0.018, 2.645], atol=5e-3)


def test_jacobians_match_finite_differences():
    x = np.array([17.5, -0.35, 0.45])
    u = np.array([-0.2, 3500.0])
    a_mat, b_mat = jacobians(x, u, MODEL)
    for j, h in enumerate((1e-5, 1e-7, 1e-7)):
        dx = np.zeros(3)
        dx[j] = h
        fd = (drift_derivatives_vec(x + dx, u, MODEL) - drift_derivatives_vec(x - dx, u, MODEL)) / (2 * h)
        np.testing.assert_allclose(a_mat[:, j], fd, rtol=1e-5, atol=1e-6)
    for j, h in enumerate((1e-7, 1e-2)):
        du = np.zeros(2)
        du[j] = h
        fd = (drift_derivatives_vec(x, u + du, MODEL) - drift_derivatives_vec(x, u - du, MODEL)) / (2 * h)
        np.testing.assert_allclose(b_mat[:, j], fd, rtol=1e-5, atol=1e-9)


def test_countersteer_branch_sign_convention(left_eq):
    assert left_eq.yaw_rate_radps > 0 and left_eq.steer_rad < 0 and left_eq.drive_force_n > 0


@pytest.mark.parametrize("beta", [0.9, -1.0])
def test_no_equilibrium_is_a_clear_error(beta):
    with pytest.raises(NoEquilibriumError, match="radius=44.0.*beta"):
        drift_equilibrium(44.0, beta, MODEL)


def test_load_transfer_without_more_grip_removes_the_drift():
    # docs/reference.md, The car: a CG height of 0.2 m already removes the beta = -0.4 drift of this car.
    plant = PlantConfig(friction_scale=1.0, tyre_c_scale=1.0, friction_circle=False, cg_height_m=0.2)
    with pytest.raises(NoEquilibriumError):
        drift_equilibrium(44.0, -0.4, plant.packed_params(VehicleParams()))


def test_default_plant_has_its_own_drift_near_the_model(left_eq):
    plant_eq = drift_equilibrium(44.0, -0.4, PlantConfig().packed_params(VehicleParams()))
    assert abs(plant_eq.speed_mps - left_eq.speed_mps) < 1.5
    assert abs(plant_eq.steer_rad - left_eq.steer_rad) < 0.1


def test_vehicle_validation_names_the_field():
    with pytest.raises(ConfigError, match="vehicle.friction"):
        VehicleParams(friction=-1.0)


def test_the_compiled_equilibrium_residual_is_the_python_arithmetic_bit_for_bit():
    """The equilibrium solver's residual runs compiled; on random unknowns (NaN included) it gives exactly what
    the same operations give in Python, so every equilibrium, and every episode, keeps its bits."""
    import math

    from driftlab.core.config import EpisodeConfig
    from driftlab.core.equilibrium import _residual
    from driftlab.core.vehicle import drift_derivatives, pack_params

    def in_python(unknowns, radius_m, sideslip_rad, p):
        speed, steer, drive_kn = unknowns
        speed = max(speed, 0.1)
        d = drift_derivatives(speed, sideslip_rad, speed / radius_m, steer, drive_kn * 1e3, p)
        return np.array([d[0], d[1] * speed, d[2]])

    p = pack_params(EpisodeConfig().vehicle)
    rng = np.random.default_rng(7)
    for _ in range(3000):
        unknowns = np.array([rng.uniform(-5.0, 40.0), rng.uniform(-1.0, 1.0), rng.uniform(-5.0, 15.0)])
        radius, beta = rng.uniform(20.0, 80.0), rng.uniform(-0.7, -0.1)
        assert np.array_equal(_residual(unknowns, radius, beta, p), in_python(unknowns, radius, beta, p))
    nan = np.array([math.nan, 0.1, 1.0])
    assert np.isnan(_residual(nan, 44.0, -0.4, p)).all() and np.isnan(in_python(nan, 44.0, -0.4, p)).all()
