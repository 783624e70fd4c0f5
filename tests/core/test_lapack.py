"""The direct LAPACK calls return scipy.linalg's bits, whichever order the factor is stored in."""

import numpy as np
import pytest
from scipy.linalg import LinAlgError, cho_solve, cholesky, solve_triangular

from driftlab.core.lapack import cho_solve_lower, cholesky_lower, solve_lower


@pytest.mark.parametrize("n", [1, 7, 150, 343])
def test_the_same_bits_as_scipy_linalg(n):
    rng = np.random.default_rng(n)
    a = rng.random((n, n))
    a = a @ a.T + n * np.eye(n)
    chol = cholesky_lower(a)
    assert np.array_equal(chol, cholesky(a, lower=True, check_finite=False))
    for b in (rng.random(n), rng.random((n, 7))):
        assert np.array_equal(cho_solve_lower(chol, b), cho_solve((chol, True), b, check_finite=False))
        for factor in (chol, np.ascontiguousarray(chol)):  # Fortran order from LAPACK, C order from a block update
            assert np.array_equal(solve_lower(factor, b), solve_triangular(factor, b, lower=True, check_finite=False))
        np.testing.assert_allclose(chol @ solve_lower(chol, b), b, rtol=1e-12, atol=1e-12)


def test_a_matrix_that_is_not_positive_definite_is_refused():
    with pytest.raises(LinAlgError, match="not positive definite"):
        cholesky_lower(np.array([[1.0, 2.0], [2.0, 1.0]]))
