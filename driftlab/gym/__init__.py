"""DriftLab's figure 8 as a Gymnasium environment (docs/gym.md): ``DriftLab/Figure8-v0``, registered on import.

    import gymnasium as gym
    import driftlab.gym
    env = gym.make("DriftLab/Figure8-v0", plant="commonroad_std", config={"scenario.sideslip_rad": 0.5})

(or ``gym.make("driftlab.gym:DriftLab/Figure8-v0", ...)``, which imports this package itself). A package at the
edge: it imports driftlab.core and gymnasium only (the ``gym`` extra; ``rl`` adds a learner).
"""

from __future__ import annotations

import gymnasium

from driftlab.gym.env import FigureEightEnv, episode_config
from driftlab.gym.mpc_policy import MpcPolicy, mpc_policy
from driftlab.gym.spaces import ACTION_NAMES, OBSERVATION_NAMES

ENV_ID = "DriftLab/Figure8-v0"

__all__ = ["ACTION_NAMES", "ENV_ID", "OBSERVATION_NAMES", "FigureEightEnv", "MpcPolicy", "episode_config",
           "mpc_policy", "register_envs"]


def register_envs() -> None:
    """Register ``DriftLab/Figure8-v0`` (once; importing this package does it). No step limit of Gymnasium's: the
    episode truncates itself at the scenario's max_time_s."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="driftlab.gym.env:FigureEightEnv")


register_envs()
