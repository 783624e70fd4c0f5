"""The direct MINPACK call is scipy.optimize.root(method="hybr") to the bit, on the residuals it solves: every start
of a drift equilibrium (the converging and the failing ones) and of a CommonRoad car's drift family."""

from itertools import product

import numpy as np
from scipy.optimize import root

from driftlab.core import equilibrium
from driftlab.core.commonroad import equilibrium as commonroad_equilibrium
from driftlab.core.commonroad.parameters import pack_commonroad
from driftlab.core.minpack import hybr
from driftlab.core.vehicle import VehicleParams, pack_params


def _same_as_root(residual, start, args, **options):
    solved = root(residual, np.array(start, float), args=args, method="hybr", options=options)
    x, converged = hybr(residual, np.array(start, float), args, **options)
    assert np.array_equal(x, solved.x, equal_nan=True)
    assert converged == solved.success
    return converged


def test_every_start_of_a_drift_equilibrium():
    p = pack_params(VehicleParams())
    starts = product(equilibrium._START_SPEEDS_MPS, equilibrium._START_STEERS_RAD, equilibrium._START_DRIVE_KN)
    converged = [_same_as_root(equilibrium._residual, s, (44.0, -0.4, p)) for s in starts]
    assert any(converged)
    _same_as_root(equilibrium._residual, [19.0, -0.2, 4.0], (44.0, -0.4, p), xtol=1e-14)  # the polish


def test_starts_that_fail_fail_alike():
    p = pack_params(VehicleParams())
    converged = [_same_as_root(equilibrium._residual, start, (44.0, -1.1, p))
                 for start in product((0.0, 0.5, 100.0, 1e4), (-1.5, 1.5), (-50.0, 50.0))]
    assert not all(converged)


def test_a_commonroad_family_start():
    cp = np.ascontiguousarray(pack_commonroad(2), dtype=np.float64)
    wheel = cp[commonroad_equilibrium.CR_WHEEL_RADIUS]
    for speed, steer, slip in product((10.0, 17.0), (-0.3, 0.2), (-0.8, -2.0)):
        ground = speed * np.cos(-0.5) / wheel
        guess = [speed, steer, ground, ground * (1.0 - slip), 3.0]
        _same_as_root(commonroad_equilibrium._residual, guess, (44.0, -0.5, cp), xtol=1e-12)
