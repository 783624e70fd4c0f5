"""The figure 8 as a Gymnasium environment: DriftLab's episode, a policy in the controller's place.

An episode of the environment is the episode `driftlab episode` runs (driftlab.core.episode): the same config
(preset, ``--set`` keys, the controller's model fitted to the plant), the same start in the scenario's first drift
and the same plant variation and measurement noise for a seed, the same planner and failure rules, all of it the
closed loop's own compiled code (driftlab.core.closed_loop.observe). Only the commands come from outside: each
:meth:`FigureEightEnv.step` sends them for one control step (``mpc.dt_s``). Driven by the MPC's own commands
(driftlab.gym.mpc_policy) it reproduces `driftlab episode` bit for bit.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from numba import typeof

from driftlab.core.config import EpisodeConfig, Theta
from driftlab.core.configure import apply_overrides, fitted, preset_config
from driftlab.core.drivability import check_drivable
from driftlab.core.episode import EpisodeResult, EpisodeRun, episode_result, start_episode
from driftlab.core.errors import ConfigError, NoEquilibriumError
from driftlab.core.loop_state import I_STATUS, I_STEP, RUNNING, STALLED, STATUSES
from driftlab.core.metrics import objective_of_costs
from driftlab.core.plant import PLANT_EXTERNAL
from driftlab.core.variation import MAX_SEED
from driftlab.gym.kernels import COST, N_OBSERVATION, act, env_step, sense
from driftlab.gym.spaces import action_bounds, action_space, observation_space

RUNNING_STATUS = "running"


def episode_config(plant: str = "default", controller: str = "default",
                   config: dict[str, Any] | None = None) -> EpisodeConfig:
    """The config `driftlab episode --plant P --controller C --set k=v ...` runs: the preset, the dotted keys, the
    drivability check and the controller's model fitted to the plant.

    Raises:
        ConfigError: an unknown preset or key, a bad value (naming the key), or a scenario the car cannot drive.
    """
    parsed = apply_overrides(preset_config(plant, controller), dict(config or {}))
    check_drivable(parsed)
    return fitted(parsed)


def _compiled(dispatcher, *args):
    """The compiled function for these arguments' types, called without numba's per-call type resolution (which
    costs ~10 us for the loop's named tuples, more than the default plant's step)."""
    try:
        return dispatcher.compile(tuple(typeof(arg) for arg in args))
    except Exception:  # noqa: BLE001  # numba's internals moved: the dispatcher itself is as correct, only slower
        return dispatcher


class FigureEightEnv(gym.Env):
    """DriftLab's figure-8 drift (registered as ``DriftLab/Figure8-v0``).

    Spaces, reward and ending (docs/gym.md): the observation and the action are :mod:`driftlab.gym.spaces`'s; the
    reward of a step is minus the stage cost of the state it reached, |e| + 5 |dpsi| + |beta - beta_eq| (paper
    eq. 12), so that J = log(mean(costs)) over the reset's ``info["stage_cost"]`` and every step's -reward
    (:meth:`objective_j`); the episode terminates where the episode runner ends it (spun out, left the track,
    stalled, gripped up, diverged, invalid plant; completed: the 8 finished) and is truncated at
    ``scenario.max_time_s`` x ``scenario.laps`` (status "stalled", as the runner says of an unfinished 8).

    Args:
        plant: a ``--plant`` preset ("default", "nominal", "commonroad_std", "commonroad_mb", or an installed plant).
        controller: "default" or "paper": the MPC's settings (the action's bounds; what driftlab.gym.mpc_policy
            drives with).
        config: dotted keys as `driftlab --set` takes them, e.g. ``{"scenario.sideslip_rad": 0.5}``.
        theta: the learned parameters (c_lr, c_rl, dV, k, ...): the planner's triggers and the reference speed are
            the environment's; k is the MPC policy's steering feedback.
        render_mode: none is supported (the 3D view replays stored episodes).

    Raises:
        ConfigError: a bad preset, key or value (naming it), or a theta whose controller's model cannot drift.
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012  # Gymnasium's class attribute

    def __init__(self, plant: str = "default", controller: str = "default", config: dict[str, Any] | None = None,
                 theta: dict[str, float] | None = None, render_mode: str | None = None) -> None:
        if render_mode is not None:
            raise ConfigError(f"render_mode: DriftLab's environment renders nothing, got {render_mode!r}")
        self.episode_config = episode_config(plant, controller, config)
        self.theta = Theta.from_mapping(dict(theta or {}))
        self.run: EpisodeRun | None = None
        self.result: EpisodeResult | None = None
        self.costs: list[float] = []
        self._buffer = np.zeros(N_OBSERVATION + 1)  # the kernels write the observation and the stage cost here
        self._kernels: dict[Any, Any] = {}
        qa = self._start(0).model.left_qp.arrays  # refuses a theta without drift here, not at the first reset
        low, high = action_bounds(qa)
        self._steer_low, self._drive_low = float(low[0]), float(low[1])
        self._steer_high, self._drive_high = float(high[0]), float(high[1])
        self.action_space = action_space(qa)
        self.observation_space = observation_space()

    def _start(self, seed: int) -> EpisodeRun:
        try:
            return start_episode(self.theta, self.episode_config, seed)
        except NoEquilibriumError as exc:
            raise ConfigError(f"theta's model corrections leave the controller's model without a drift to hold: "
                              f"{exc}", field="theta") from exc

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode: ``seed`` is `driftlab episode --seed`'s (an integer in [0, 2^63 - 1]); without one, the
        next seed is drawn from the environment's generator (Gymnasium's ``np_random``)."""
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int | np.integer)
                                 or not 0 <= seed <= MAX_SEED):
            raise ConfigError(f"seed must be an integer in [0, {MAX_SEED}], got {seed!r}", field="seed")
        super().reset(seed=None if seed is None else int(seed))
        episode_seed = int(seed) if seed is not None else int(self.np_random.integers(0, MAX_SEED, endpoint=True))
        run = self._start(episode_seed)
        self.run, self.result = run, None
        self._bind(run)
        status = self._sense()
        cost = float(self._buffer[COST])
        self.costs = [cost]
        return self._buffer[:N_OBSERVATION].copy(), {"status": RUNNING_STATUS if status == RUNNING else
                                                     STATUSES[status], "stage_cost": cost, "seed": episode_seed}

    def _bind(self, run: EpisodeRun) -> None:
        """This episode's kernel calls, their arguments fixed."""
        s, loop, model = run.settings, run.loop, run.model
        qa_left, qa_right = model.left_qp.arrays, model.right_qp.arrays
        plant_params, actuators = run.plant_args
        noise, buffer = run.noise, self._buffer
        sense_fn = self._kernel(sense, s, loop, qa_left, qa_right, noise, buffer)
        self._sense = lambda: sense_fn(s, loop, qa_left, qa_right, noise, buffer)
        self._external = s.plant_kind == PLANT_EXTERNAL
        if self._external:
            act_fn = self._kernel(act, s, loop, plant_params, actuators, 0.0, 0.0)
            self._act = lambda steer, drive: act_fn(s, loop, plant_params, actuators, steer, drive)
        else:
            step_fn = self._kernel(env_step, s, loop, qa_left, qa_right, plant_params, actuators, noise, 0.0, 0.0,
                                   buffer)
            self._step = lambda steer, drive: step_fn(s, loop, qa_left, qa_right, plant_params, actuators, noise,
                                                      steer, drive, buffer)

    def _kernel(self, dispatcher: Any, *args: Any) -> Any:
        """The compiled ``dispatcher`` for these arguments, resolved at the first episode: every episode of one
        config passes arguments of the same types (resolving them costs ~5 ms an episode)."""
        if dispatcher not in self._kernels:
            self._kernels[dispatcher] = _compiled(dispatcher, *args)
        return self._kernels[dispatcher]

    def _commands(self, action: Any) -> tuple[float, float]:
        """The action as [delta rad, Fxr N] clipped into the action space (a command inside it passes unchanged).

        Raises:
            ValueError: not two finite numbers.
        """
        try:
            steer, drive = float(action[0]), float(action[1])
            extra = len(action) != 2
        except (TypeError, IndexError, ValueError):
            raise ValueError(f"an action is [delta rad, Fxr N], got {action!r}") from None
        if extra or not (math.isfinite(steer) and math.isfinite(drive)):
            raise ValueError(f"an action is two finite numbers [delta rad, Fxr N], got {action!r}")
        return min(max(steer, self._steer_low), self._steer_high), min(max(drive, self._drive_low), self._drive_high)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Send [delta rad, Fxr N] for one control step; out-of-bounds commands are clipped to the action space."""
        run = self.run
        if run is None or self.result is not None:
            raise gym.error.ResetNeeded("call reset() before step(), and again once an episode has ended")
        loop = run.loop
        if loop.ints[I_STATUS] != RUNNING:  # ended by its policy (the MPC's failed solve): no step
            return self._ended(0.0, False)
        steer, drive = self._commands(action)
        if self._external:
            self._act(steer, drive)
            if run.step_python_plant():  # the plant ended it (invalid) before the next step was observed
                return self._ended(0.0, False)
            status = self._sense()
        else:
            status = self._step(steer, drive)
        cost = float(self._buffer[COST])
        self.costs.append(cost)
        if status != RUNNING:
            return self._ended(-cost, False)
        if loop.ints[I_STEP] < run.settings.n_steps:
            return self._buffer[:N_OBSERVATION].copy(), -cost, False, False, {"status": RUNNING_STATUS}
        # The last step of max_time_s observed: the runner would step the plant once more and stop, its status that
        # of an unfinished 8.
        loop.ints[I_STATUS] = STALLED
        return self._ended(-cost, True)

    def _ended(self, reward: float, truncated: bool) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """The last step: the runner's result (status, J, metrics) in ``info``."""
        assert self.run is not None
        self.result = episode_result(self.run)
        observation = self._buffer[:N_OBSERVATION].copy()
        if not np.all(np.isfinite(observation)):  # a diverged plant: the space holds no NaN
            observation = np.nan_to_num(observation, nan=0.0)
        info = {"status": self.result.status, "J": self.result.J, "episode": self.result.summary()}
        return observation, float(reward), not truncated, truncated, info

    def objective_j(self) -> float:
        """J of the costs so far (paper eq. 12): equal, to the bit, to the runner's J of a completed episode."""
        return objective_of_costs(self.costs)
