"""DAQP called from the compiled loop gives what daqp.solve gives, to the bit, and an episode drives the same."""

import daqp
import numpy as np
import pytest

import driftlab.core.episode as episode_module
from driftlab.core.config import Theta
from driftlab.core.configure import apply_overrides, preset_config
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.mpc import ReferenceQp, constrained_terms, daqp_kernel, reference_terms, unconstrained_increments
from driftlab.core.mpc.daqp_kernel import PROBLEM_WORDS, RESULT_WORDS, SETTINGS_WORDS, quadprog, quadprog_address
from driftlab.core.vehicle import VehicleParams, pack_params

P = pack_params(VehicleParams())
THETA = Theta(c_lr=0.0225, c_rl=0.0218, dV=-0.064, k=0.057)


def _constrained_problems(count: int) -> list[tuple[ReferenceQp, np.ndarray, np.ndarray, np.ndarray]]:
    """Steps of the default MPC whose unconstrained minimizer breaks a limit, from states scattered about the
    drift (some far enough that no increment sequence meets every limit)."""
    rng = np.random.default_rng(7)
    qp = ReferenceQp(preset_config("default").mpc, drift_equilibrium(44.0, -0.4, P), P, 0.05, 5.0)
    qa = qp.arrays
    z_ref = qa.z_eq.copy()
    ref_gain, ref_linear = reference_terms(qa, z_ref)
    problems = []
    while len(problems) < count:
        z_now = qa.z_lin + rng.normal(0.0, 1.0, qa.z_lin.shape) * np.array([3, .3, .3, 2, .3, .3, 3, .3, 3])
        disturbance = rng.normal(0.0, 0.5, 3)
        du, dz, offset, within = unconstrained_increments(qa, z_now, ref_gain, disturbance)
        if not within:
            problems.append((qp, *constrained_terms(qa, dz, disturbance, ref_linear, offset)))
    return problems


def test_the_kernels_solve_is_daqp_solve_to_the_bit():
    function = quadprog_address()
    assert function != 0  # the locked daqp is the release the structs are laid out for
    buffers = (np.zeros(PROBLEM_WORDS, np.int64), np.zeros(RESULT_WORDS, np.int64), np.zeros(SETTINGS_WORDS, np.int64))
    flags = set()
    for qp, q, lower, upper in _constrained_problems(300):
        x_ref, _, flag_ref, info = daqp.solve(qp.hessian, q, qp.cumsum, upper, lower, qp.daqp_sense)
        x, lam = np.full(len(q), np.nan), np.full(len(upper), np.nan)
        flag = quadprog(function, qp.hessian, q, qp.cumsum, upper, lower, qp.daqp_sense, x, lam, *buffers)
        assert flag == flag_ref
        assert x.tobytes() == np.asarray(x_ref).tobytes()
        if flag > 0:  # DAQP writes every multiplier only where it solved
            assert lam.tobytes() == np.asarray(info["lam"]).tobytes()
        flags.add(flag)
    assert 1 in flags and min(flags) < 0  # solved problems and infeasible ones, both as daqp.solve reports them
    assert not qp.daqp_sense.any()  # the senses are read, never written: every solve starts cold


# MB's published model (wheels held to the road), where this theta drives the whole 8 (docs/results.md).
_OVERRIDES = {"commonroad_mb": {"plant.wheel_liftoff": False, "failure.max_invalid_s": 300.0}}


@pytest.mark.parametrize("plant", ["default", "commonroad_std", "commonroad_mb"])
def test_an_episode_drives_the_same_whether_the_kernel_or_python_solves(plant, monkeypatch):
    config = apply_overrides(preset_config(plant), _OVERRIDES.get(plant, {}))
    assert config.mpc.qp_solver == "daqp"
    in_kernel = episode_module.run_episode(THETA, config, seed=2)
    assert in_kernel.trajectory[:, episode_module.COL["osqp"]].sum() > 5  # it had constrained steps to solve
    monkeypatch.setattr(episode_module, "quadprog_address", lambda: 0)  # back to Python's daqp.solve
    in_python = episode_module.run_episode(THETA, config, seed=2)
    assert in_kernel.J == in_python.J and in_kernel.status == in_python.status
    assert np.array_equal(in_kernel.trajectory, in_python.trajectory)


def test_another_daqp_release_leaves_the_solve_to_python(monkeypatch):
    quadprog_address.cache_clear()
    monkeypatch.setattr(daqp_kernel, "version", lambda name: "0.12.0")
    try:
        assert quadprog_address() == 0
    finally:
        quadprog_address.cache_clear()


def test_osqp_is_still_solved_in_python():
    config = apply_overrides(preset_config("default"), {"mpc.qp_solver": "osqp"})
    run = episode_module.start_episode(THETA, config, 0)
    assert run.settings.daqp_function == 0
