"""Acquisition functions for minimization: expected improvement and the success constraint.

Pure functions of the surrogate's predictions, kept apart from the surrogate and the ask/tell loop as BoTorch
and scikit-optimize keep them.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr

from driftlab.core.nearest import nearest_squared_distances

_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)


def expected_improvement(mean: np.ndarray, std: np.ndarray, best: float, xi: float = 0.0) -> np.ndarray:
    """E[max(best - xi - f, 0)] for f ~ N(mean, std^2) (Jones, Schonlau & Welch 1998)."""
    std = np.maximum(std, 1e-12)
    gap = best - mean - xi
    z = gap / std
    return gap * ndtr(z) + std * _INV_SQRT_2PI * np.exp(-0.5 * z * z)


def failure_clearance(x: np.ndarray, failed: np.ndarray, radius: float) -> np.ndarray:
    """1 - exp(-(d / radius)^2), d the distance to the nearest failed point (1 with no failures): where a failure
    boundary runs close past the optimum, the classifier still says "likely success" right next to a failure,
    and EI would propose the same failing point again and again."""
    if len(failed) == 0:
        return np.ones(len(x))
    return 1.0 - np.exp(-nearest_squared_distances(x, failed) / radius**2)


def constrained_ei(ei: np.ndarray, p_success: np.ndarray, clearance: np.ndarray, min_probability: float) -> np.ndarray:
    """EI weighted by P(success), and zero where success is less likely than ``min_probability`` (a probabilistic
    constraint, Gelbart, Snoek & Adams 2014): where the regressor has no data its EI is large, and a soft weight
    alone lets it keep probing the failing region."""
    return ei * p_success * (p_success >= min_probability) * clearance
