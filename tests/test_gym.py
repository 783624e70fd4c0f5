"""The Gymnasium environment (driftlab.gym): Gymnasium's own checker, the runner's episode bit for bit under the MPC's
commands, its config refusals, clipped actions and the ends of an episode. Real solvers and plants, no mocks."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import driftlab.gym
from driftlab.core.config import Theta
from driftlab.core.episode import failure_penalty, run_episode
from driftlab.core.errors import ConfigError
from driftlab.gym import ENV_ID, FigureEightEnv, mpc_policy

# One worker compiles the environment's kernels for all of these (pytest-xdist --dist loadgroup).
pytestmark = pytest.mark.xdist_group("gym")


def _mpc_episode(env, seed):
    """An episode of ``env`` driven by the MPC's own commands: (steps, last info)."""
    policy = mpc_policy(env)
    observation, info = env.reset(seed=seed)
    steps, ended = 0, False
    while not ended:
        observation, _, terminated, truncated, info = env.step(policy(observation))
        steps, ended = steps + 1, terminated or truncated
    return steps, info


@pytest.mark.parametrize("plant", ["default", "commonroad_std", "commonroad_mb"])
def test_gymnasiums_checker_passes(plant):
    env = gym.make(ENV_ID, plant=plant)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its advice: a normalized action Box, finite observation bounds
        check_env(env.unwrapped)
    assert env.observation_space.shape == (len(driftlab.gym.OBSERVATION_NAMES),)
    assert env.action_space.shape == (2,)


@pytest.mark.parametrize(("plant", "controller", "seed", "config"), [
    ("default", "default", 3, {}),
    ("nominal", "paper", 0, {}),
    ("commonroad_std", "default", 1, {}),
])
def test_the_mpc_driven_episode_is_the_runners_bit_for_bit(plant, controller, seed, config):
    env = gym.make(ENV_ID, plant=plant, controller=controller, config=config)
    steps, info = _mpc_episode(env, seed)
    result = run_episode(Theta(), env.unwrapped.episode_config, seed=seed)
    assert info["status"] == result.status == "completed"
    assert info["J"] == result.J
    assert env.unwrapped.objective_j() == result.J  # the rewards' J, not approximately
    assert np.array_equal(env.unwrapped.result.trajectory, result.trajectory)
    assert steps == len(result.trajectory) - 1  # the first row is the reset's
    assert info["episode"]["completed_fraction"] == 1.0


def test_the_cli_figures_come_out_of_the_environment():
    # `driftlab episode --seed 3` and `driftlab episode --plant nominal --controller paper`. Their last digits
    # follow the CPU (OpenBLAS picks its kernels by instruction set: -1.5448774884742065 with AVX-512,
    # -1.5448774883161882 with OPENBLAS_CORETYPE=Haswell), so to 1e-9, as the stored-release check does.
    for kwargs, seed, expected in (({}, 3, -0.5858037297916099),
                                   ({"plant": "nominal", "controller": "paper"}, 0, -1.5448774884742065)):
        env = gym.make(ENV_ID, **kwargs)
        _mpc_episode(env, seed)
        assert env.unwrapped.objective_j() == pytest.approx(expected, abs=1e-9)


def test_rewards_are_minus_the_stage_costs_of_j():
    env = gym.make(ENV_ID)
    policy = mpc_policy(env)
    observation, info = env.reset(seed=3)
    rewards = []
    for _ in range(40):
        observation, reward, *_ = env.step(policy(observation))
        rewards.append(reward)
    rows = env.unwrapped.run.loop.rows[:41]
    cost = np.abs(rows[:, 12]) + 5.0 * np.abs(rows[:, 13]) + np.abs(rows[:, 5] - rows[:, 17])  # e, dpsi, beta, beta_ref
    assert info["stage_cost"] == cost[0]
    assert np.array_equal(-np.array(rewards), cost[1:])


def test_a_bad_config_key_is_refused_naming_it():
    with pytest.raises(ConfigError, match="scenario.no_such_key") as caught:
        gym.make(ENV_ID, config={"scenario.no_such_key": 1.0})
    assert caught.value.field == "scenario.no_such_key"
    with pytest.raises(ConfigError, match="scenario.sideslip_rad"):
        FigureEightEnv(config={"scenario.sideslip_rad": "steep"})
    with pytest.raises(ConfigError, match="plant must be one of"):
        FigureEightEnv(plant="no_such_plant")


def test_the_config_is_the_clis():
    env = FigureEightEnv(plant="commonroad_std", config={"scenario.sideslip_rad": 0.55, "mpc.horizon": "15"})
    assert env.episode_config.scenario.sideslip_rad == 0.55
    assert env.episode_config.mpc.horizon == 15
    assert not env.episode_config.to_fit  # fitted, as `driftlab episode` runs it


def test_an_action_outside_the_box_is_clipped_to_it_and_a_non_finite_one_refused():
    env = FigureEightEnv()
    low, high = env.action_space.low, env.action_space.high
    assert high[0] == 0.6 and low[0] == -0.6 and low[1] == pytest.approx(-6000.0) and high[1] == pytest.approx(8000.0)
    env.reset(seed=5)
    clipped = env.step(np.array([3.0, 1e6]))[0]
    env.reset(seed=5)
    bounded = env.step(high)[0]
    assert np.array_equal(clipped, bounded)
    for bad in ([np.nan, 0.0], [0.0, np.inf], [0.1], "left"):
        with pytest.raises(ValueError, match="action"):
            env.step(bad)


def test_spinning_out_terminates_with_the_runners_status_and_penalty():
    env = FigureEightEnv()
    env.reset(seed=0)
    steps, terminated, truncated = 0, False, False
    while not (terminated or truncated):  # full lock the wrong way, full drive: the car spins
        _, reward, terminated, truncated, info = env.step([0.6, 8000.0])
        steps += 1
    assert terminated and not truncated and steps < 100
    assert info["status"] in ("spun_out", "left_track", "gripped_up")
    assert info["J"] == failure_penalty(info["episode"]["completed_fraction"])
    assert reward < 0.0
    with pytest.raises(gym.error.ResetNeeded):
        env.step([0.0, 0.0])


def test_max_time_truncates_as_an_unfinished_eight():
    env = FigureEightEnv(config={"scenario.max_time_s": 2.0})
    steps, info = _mpc_episode(env, 3)
    result = run_episode(Theta(), env.unwrapped.episode_config, seed=3)
    assert steps == 40 and info["status"] == result.status == "stalled"
    assert info["J"] == result.J
    assert np.array_equal(env.unwrapped.result.trajectory[:, :7], result.trajectory[:, :7])


def test_reset_without_a_seed_draws_one_from_the_environments_generator():
    env = FigureEightEnv(plant="default")
    _, first = env.reset(seed=11)
    _, drawn = env.reset()
    _, again = env.reset(seed=11)
    _, drawn_again = env.reset()
    assert first["seed"] == again["seed"] == 11 and drawn["seed"] == drawn_again["seed"] != 11
    with pytest.raises(ConfigError, match="seed"):
        env.reset(seed=-1)


def test_the_module_path_form_registers_the_environment():
    env = gym.make("driftlab.gym:DriftLab/Figure8-v0", plant="nominal")
    assert isinstance(env.unwrapped, FigureEightEnv)
