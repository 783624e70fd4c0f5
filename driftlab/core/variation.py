"""Per-episode variation: what one seed changes in the plant, the start and the measurements.

A real car never drives the same episode twice: friction and load differ a little, the actuators differ, the
sensors are noisy. :func:`draw_variation` turns a seed into one such episode, as a pure function of
(plant config, seed), so that an episode stays a pure function of (theta, config, seed). The spreads are
settings of :class:`~driftlab.core.plant.PlantConfig` (all zero in the nominal plant).

The draws use NumPy's PCG64 through a ``SeedSequence``: the same seed gives the same numbers on any
platform and in any process. Parameter, start and noise draws come from separate child streams, so that
turning the noise up does not change which car a seed draws.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from driftlab.core.plant import PLANT_LIMITS, VARIATION_LIMITS, PlantConfig
from driftlab.core.plants import entry_of

# Measurement noise columns.
NOISE_X, NOISE_Y, NOISE_HEADING, NOISE_SPEED, NOISE_SIDESLIP, NOISE_YAW_RATE = range(6)
MAX_SEED = 2**63 - 1


@dataclass(frozen=True)
class EpisodeVariation:
    """One seed's episode.

    Attributes:
        plant: the plant config with this episode's friction, mass and steering lag.
        start_offset: added to the start [V m/s, beta rad, r rad/s].
        noise: (n_steps, 6) measurement noise per control step, columns x m, y m, psi rad, V m/s, beta rad,
            r rad/s (all zero when the plant has no noise).
    """

    plant: PlantConfig
    start_offset: np.ndarray
    noise: np.ndarray

    @property
    def noisy(self) -> bool:
        return bool(np.any(self.noise))


def _uniform(rng: np.random.Generator, spread: float) -> float:
    return float(rng.uniform(-1.0, 1.0) * spread)


def _within(name: str, value: float) -> float:
    lo, hi = PLANT_LIMITS[name]
    return min(max(value, lo), hi)


SPENT_SPREADS: dict[str, Any] = dict.fromkeys(VARIATION_LIMITS, 0.0)


def draw_variation(plant: PlantConfig, seed: int, n_steps: int) -> EpisodeVariation:
    """The episode of ``seed`` (an integer in [0, 2^63 - 1]) for a plant config and ``n_steps`` control steps."""
    params_rng, start_rng, noise_rng = (np.random.default_rng(child)
                                        for child in np.random.SeedSequence(seed).spawn(3))
    friction_factor = 1.0 + _uniform(params_rng, plant.friction_spread)
    mass_factor = 1.0 + _uniform(params_rng, plant.mass_spread)
    steer_lag_s = plant.steer_lag_s + _uniform(params_rng, plant.steer_lag_spread_s)
    # The drawn car is a concrete plant: its own spreads are spent.
    varied = replace(
        plant,
        friction_scale=_within("friction_scale", plant.friction_scale * friction_factor),
        # A heavier load raises the yaw inertia with it (m k^2, the radius of gyration unchanged).
        mass_scale=_within("mass_scale", plant.mass_scale * mass_factor),
        # (A CommonRoad plant scales its yaw inertia with mass_scale itself.)
        yaw_inertia_scale=_within("yaw_inertia_scale", plant.yaw_inertia_scale * mass_factor)
        if not entry_of(plant).own_car else plant.yaw_inertia_scale,
        steer_lag_s=_within("steer_lag_s", steer_lag_s),
        **SPENT_SPREADS,
    )
    start = np.array([_uniform(start_rng, plant.initial_speed_spread_mps),
                      _uniform(start_rng, plant.initial_sideslip_spread_rad),
                      _uniform(start_rng, plant.initial_yaw_rate_spread_radps)])
    std = np.array([plant.noise_position_m, plant.noise_position_m, plant.noise_heading_rad, plant.noise_speed_mps,
                    plant.noise_sideslip_rad, plant.noise_yaw_rate_radps])
    noise = noise_rng.standard_normal((n_steps, len(std))) * std if np.any(std) else np.zeros((n_steps, len(std)))
    return EpisodeVariation(varied, start, noise)
