"""A learned policy as a file any DriftLab install can run: a multilayer perceptron's weights in a NumPy ``.npz``,
evaluated with NumPy alone (no learning library at run time), deterministically (the mean action).

Two forms (``mode``):

- ``direct``: the policy's output, squashed by tanh into [-1, 1], is the command scaled into the action space
  [delta rad, Fxr N] (Stable-Baselines3's SAC actor and its ``unscale_action``).
- ``residual``: the policy adds to the MPC's command: its input is the observation followed by the MPC's command
  for the step, and its tanh output times ``residual_scale`` (per command, in rad and N) is added to that command
  (:class:`ResidualMpcEnv` is the environment it learns in).

File keys: ``mode`` ("direct" | "residual"), ``obs_mean`` and ``obs_std`` (the input is (x - mean) / std),
``residual_scale`` (residual only), ``layers`` (n), ``w0``/``b0`` ... ``w{n-1}``/``b{n-1}`` (ReLU between layers,
none after the last; ``w`` is out x in, as torch stores a Linear's weight) and ``trained_on`` (a JSON text: what it
was trained on, with the command).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from driftlab.core.errors import ConfigError
from driftlab.gym.env import FigureEightEnv
from driftlab.gym.mpc_policy import MpcPolicy
from driftlab.gym.spaces import N_OBSERVATION

MODES = ("direct", "residual")


@dataclass(frozen=True)
class MlpPolicy:
    """A deterministic policy network: ReLU hidden layers, tanh on the output (in [-1, 1] per command)."""

    mode: str
    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    obs_mean: np.ndarray
    obs_std: np.ndarray
    residual_scale: np.ndarray = field(default_factory=lambda: np.zeros(2))
    trained_on: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ConfigError(f"policy mode must be one of {', '.join(MODES)}, got {self.mode!r}", field="mode")
        n_in = N_OBSERVATION + (2 if self.mode == "residual" else 0)
        if not self.weights or len(self.weights) != len(self.biases):
            raise ConfigError("a policy needs at least one layer, each with its weights and biases", field="layers")
        if self.weights[0].shape[1] != n_in or self.obs_mean.shape != (n_in,) or self.obs_std.shape != (n_in,):
            raise ConfigError(f"a {self.mode} policy reads {n_in} inputs, its first layer takes "
                              f"{self.weights[0].shape[1]}", field="w0")
        if self.weights[-1].shape[0] != 2:
            raise ConfigError(f"a policy outputs 2 commands, its last layer gives {self.weights[-1].shape[0]}",
                              field=f"w{len(self.weights) - 1}")
        for i in range(1, len(self.weights)):
            if self.weights[i].shape[1] != self.weights[i - 1].shape[0]:
                raise ConfigError(f"layer {i} takes {self.weights[i].shape[1]} inputs, layer {i - 1} gives "
                                  f"{self.weights[i - 1].shape[0]}", field=f"w{i}")

    def squashed(self, inputs: np.ndarray) -> np.ndarray:
        """The network's output in [-1, 1]^2 for one input vector."""
        x = (np.asarray(inputs, dtype=np.float64) - self.obs_mean) / self.obs_std
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = w @ x + b
            if i < len(self.weights) - 1:
                x = np.maximum(x, 0.0)
        return np.tanh(x)

    def save(self, path: str) -> None:
        arrays: dict[str, Any] = {f"w{i}": w for i, w in enumerate(self.weights)}
        arrays.update({f"b{i}": b for i, b in enumerate(self.biases)})
        arrays.update(mode=np.array(self.mode), layers=np.array(len(self.weights)), obs_mean=self.obs_mean,
                      obs_std=self.obs_std, residual_scale=self.residual_scale,
                      trained_on=np.array(json.dumps(self.trained_on)))
        np.savez(path, **arrays)

    @classmethod
    def load(cls, path: str) -> MlpPolicy:
        """Raises ConfigError (naming the file) for a file that is not a DriftLab policy."""
        try:
            with np.load(path, allow_pickle=False) as data:
                n = int(data["layers"])
                return cls(mode=str(data["mode"]), weights=tuple(np.asarray(data[f"w{i}"], float) for i in range(n)),
                           biases=tuple(np.asarray(data[f"b{i}"], float) for i in range(n)),
                           obs_mean=np.asarray(data["obs_mean"], float), obs_std=np.asarray(data["obs_std"], float),
                           residual_scale=np.asarray(data["residual_scale"], float),
                           trained_on=json.loads(str(data["trained_on"])))
        except ConfigError as exc:
            raise ConfigError(f"policy file {path}: {exc}", field="controller") from exc
        except (OSError, KeyError, ValueError) as exc:
            raise ConfigError(f"policy file {path}: not a DriftLab policy (.npz with mode, layers, w0, b0, ...): "
                              f"{exc}", field="controller") from exc


class PolicyController:
    """``controller(observation) -> [delta rad, Fxr N]`` for the environment ``env``: the policy's command
    (direct), or the MPC's plus the policy's correction (residual)."""

    def __init__(self, policy: MlpPolicy, env: Any) -> None:
        unwrapped = env.unwrapped
        if not isinstance(unwrapped, FigureEightEnv):
            raise TypeError(f"a policy drives DriftLab's environment, got {type(unwrapped).__name__}")
        self.policy = policy
        space = unwrapped.action_space
        assert isinstance(space, gym.spaces.Box)
        self.low, self.high = space.low, space.high
        self.mpc = MpcPolicy(unwrapped) if policy.mode == "residual" else None

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        if self.mpc is None:
            return self.low + 0.5 * (self.policy.squashed(observation) + 1.0) * (self.high - self.low)
        base = self.mpc(observation)
        correction = self.policy.squashed(np.concatenate([observation, base])) * self.policy.residual_scale
        return np.clip(base + correction, self.low, self.high)


def residual_scale_of(env: Any, share: float) -> np.ndarray:
    """The residual's reach per command: ``share`` of each command's half-range (rad, N)."""
    space = env.unwrapped.action_space
    return share * 0.5 * (space.high - space.low)


class ResidualMpcEnv(gym.Wrapper):
    """The environment a residual policy learns in: its action in [-1, 1]^2 scales to a correction of the MPC's
    command (``residual_scale`` rad and N), its observation is the environment's followed by the MPC's command for
    the step. The reward, the ending and the seeds are the environment's."""

    def __init__(self, env: gym.Env, residual_scale: np.ndarray) -> None:
        super().__init__(env)
        self.mpc = MpcPolicy(env)
        self.residual_scale = np.asarray(residual_scale, dtype=np.float64)
        inner, space = env.observation_space, env.unwrapped.action_space
        assert isinstance(inner, gym.spaces.Box) and isinstance(space, gym.spaces.Box)
        self.observation_space = gym.spaces.Box(np.concatenate([inner.low, space.low]),
                                                np.concatenate([inner.high, space.high]),
                                                dtype=np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float64)
        self._base = np.zeros(2)

    def _observe(self, observation: np.ndarray) -> np.ndarray:
        self._base = self.mpc(observation)
        return np.concatenate([observation, self._base])

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        observation, info = self.env.reset(**kwargs)
        return self._observe(observation), info

    def step(self, action: Any) -> tuple[np.ndarray, Any, bool, bool, dict[str, Any]]:
        command = self._base + np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0) * self.residual_scale
        observation, reward, terminated, truncated, info = self.env.step(command)
        if terminated or truncated:
            return np.concatenate([observation, self._base]), reward, terminated, truncated, info
        return self._observe(observation), reward, terminated, truncated, info


def run_policy_episode(env: Any, controller: Any, seed: int) -> Any:
    """One environment episode under ``controller``; the runner's result (status, J, metrics, trajectory)."""
    observation, _ = env.reset(seed=seed)
    while True:
        observation, _, terminated, truncated, _ = env.step(controller(observation))
        if terminated or truncated:
            return env.unwrapped.result
