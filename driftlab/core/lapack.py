"""The dense solves the optimizer repeats thousands of times an ask, as calls to LAPACK itself.

scipy.linalg's ``cholesky``, ``cho_solve`` and ``solve_triangular`` validate their inputs and dispatch over batch
dimensions on every call (~20-30 us each), more than the LAPACK work of the acquisition's 7-point gradient probes.
These call the same LAPACK routines (potrf, potrs, trtrs) with the arguments those wrappers pass, including
solve_triangular's choice of layout, so they return the same bits (tests/core/test_lapack.py).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import LinAlgError
from scipy.linalg.lapack import dpotrf, dpotrs, dtrtrs


def cholesky_lower(a: np.ndarray) -> np.ndarray:
    """L with a = L L^T (scipy.linalg.cholesky(a, lower=True)); raises LinAlgError if a is not positive definite."""
    factor, info = dpotrf(a, lower=1, clean=1, overwrite_a=0)
    if info > 0:
        raise LinAlgError(f"{info}-th leading minor of the array is not positive definite")
    if info < 0:
        raise ValueError(f"illegal value in the {-info}-th argument of potrf")
    return factor


def cho_solve_lower(chol_lower: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with L L^T x = b (scipy.linalg.cho_solve((L, True), b))."""
    x, info = dpotrs(chol_lower, b, lower=1, overwrite_b=0)
    if info != 0:
        raise ValueError(f"illegal value in the {-info}-th argument of potrs")
    return x


def solve_lower(chol_lower: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with L x = b, L lower triangular (scipy.linalg.solve_triangular(L, b, lower=True)): a C-ordered L is
    solved as its transpose, as scipy does, since trtrs reads Fortran order."""
    if chol_lower.flags.f_contiguous:
        x, info = dtrtrs(chol_lower, b, lower=1, trans=0, unitdiag=0, overwrite_b=0)
    else:
        x, info = dtrtrs(chol_lower.T, b, lower=0, trans=1, unitdiag=0, overwrite_b=0)
    if info > 0:
        raise LinAlgError(f"singular matrix: resolution failed at diagonal {info - 1}")
    if info < 0:
        raise ValueError(f"illegal value in the {-info}-th argument of trtrs")
    return x
