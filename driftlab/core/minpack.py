"""Powell's hybrid method (MINPACK's hybrd), as ``scipy.optimize.root(method="hybr")`` runs it, without root's
per-call wrapping.

A drift equilibrium tries 60 starts and a model's fit solves hundreds of equilibria: root's option handling, its
check call at the start and the call counter around every residual evaluation were a third of a solve's time. This
calls the compiled MINPACK binding root itself calls, with the arguments root passes (at most 200 (n + 1)
evaluations, a dense Jacobian, machine epsilon as the difference step, factor 100), so the iterates and the answer
are root's to the bit (tests/core/test_minpack.py: a SciPy release that changes the binding fails there first).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.optimize import _minpack  # root's own binding; the public wrappers add only the overhead above

_EPSILON = float(np.finfo(np.float64).eps)
_ROOT_XTOL = 1.49012e-08  # root's default relative tolerance for hybr
_CONVERGED = 1


def hybr(residual: Callable[..., np.ndarray], x0: np.ndarray, args: tuple = (), xtol: float = _ROOT_XTOL
         ) -> tuple[np.ndarray, bool]:
    """(x, converged) of ``root(residual, x0, args=args, method="hybr", options={"xtol": xtol})``."""
    start = np.asarray(x0, dtype=np.float64).flatten()  # a copy, as root makes: MINPACK iterates in place
    solved = _minpack._hybrd(residual, start, args, 1, xtol, 200 * (len(start) + 1), -10, -10, _EPSILON, 100, None)
    return solved[0], solved[-1] == _CONVERGED
