"""A learned policy as a file (driftlab.gym.policy): its network, its file, the residual form on top of the MPC, and
`driftlab episode --controller policy:FILE`. Real plants and solvers; the networks are built here, not trained."""

import json

import numpy as np
import pytest

from driftlab.cli import main
from driftlab.core.config import Theta
from driftlab.core.episode import run_episode
from driftlab.core.errors import ConfigError
from driftlab.gym import FigureEightEnv, mpc_policy
from driftlab.gym.policy import MlpPolicy, PolicyController, ResidualMpcEnv, residual_scale_of, run_policy_episode
from driftlab.gym.spaces import N_OBSERVATION

pytestmark = pytest.mark.xdist_group("gym")  # one worker compiles the environment's kernels


def _policy(mode, n_in, hidden=8, scale=(0.1, 500.0), seed=0, out_weight=1.0):
    rng = np.random.default_rng(seed)
    return MlpPolicy(mode=mode, weights=(rng.normal(size=(hidden, n_in)), out_weight * rng.normal(size=(2, hidden))),
                     biases=(rng.normal(size=hidden), np.zeros(2)), obs_mean=rng.normal(size=n_in),
                     obs_std=rng.uniform(0.5, 2.0, size=n_in), residual_scale=np.array(scale),
                     trained_on={"command": "built by the test"})


def test_the_network_is_relu_layers_then_tanh():
    policy = _policy("direct", N_OBSERVATION)
    x = np.linspace(-1.0, 1.0, N_OBSERVATION)
    hidden = np.maximum(policy.weights[0] @ ((x - policy.obs_mean) / policy.obs_std) + policy.biases[0], 0.0)
    assert np.allclose(policy.squashed(x), np.tanh(policy.weights[1] @ hidden + policy.biases[1]), rtol=0, atol=1e-15)


def test_a_policy_file_loads_as_it_was_saved(tmp_path):
    policy = _policy("residual", N_OBSERVATION + 2)
    policy.save(tmp_path / "p.npz")
    loaded = MlpPolicy.load(str(tmp_path / "p.npz"))
    assert loaded.mode == "residual" and loaded.trained_on == {"command": "built by the test"}
    x = np.arange(N_OBSERVATION + 2, dtype=float)
    assert np.array_equal(loaded.squashed(x), policy.squashed(x))
    assert np.array_equal(loaded.residual_scale, policy.residual_scale)


def test_a_policy_of_the_wrong_shape_or_file_is_refused_naming_what(tmp_path):
    with pytest.raises(ConfigError, match="reads 19 inputs") as caught:
        _policy("residual", N_OBSERVATION)
    assert caught.value.field == "w0"
    with pytest.raises(ConfigError, match="mode must be one of direct, residual"):
        _policy("other", N_OBSERVATION)
    (tmp_path / "junk.npz").write_bytes(b"not a policy")
    with pytest.raises(ConfigError, match="junk.npz: not a DriftLab policy"):
        MlpPolicy.load(str(tmp_path / "junk.npz"))


def test_a_residual_policy_that_adds_nothing_drives_the_mpcs_episode_bit_for_bit():
    # Output weights of zero: tanh(0) = 0, no correction. The MPC's commands pass through the residual form.
    env = FigureEightEnv(plant="default")
    policy = _policy("residual", N_OBSERVATION + 2, out_weight=0.0)
    result = run_policy_episode(env, PolicyController(policy, env), seed=3)
    reference = run_episode(Theta(), env.episode_config, seed=3)
    assert result.status == reference.status == "completed"
    assert result.J == reference.J
    assert np.array_equal(result.trajectory, reference.trajectory)


def test_the_residual_training_environment_sends_the_mpcs_command_plus_the_scaled_action():
    env = FigureEightEnv(plant="default")
    scale = residual_scale_of(env, 0.2)
    assert np.allclose(scale, 0.2 * 0.5 * (env.action_space.high - env.action_space.low))
    wrapped = ResidualMpcEnv(env, scale)
    observation, _ = wrapped.reset(seed=1)
    assert observation.shape == (N_OBSERVATION + 2,) and wrapped.observation_space.contains(observation)
    action = np.array([1.0, -1.0])
    after, *_ = wrapped.step(action)
    # The same step on a plain environment of the same seed, sent the MPC's command plus the scaled action.
    plain = FigureEightEnv(plant="default")
    first, _ = plain.reset(seed=1)
    command = mpc_policy(plain)(first)
    assert np.array_equal(command, observation[N_OBSERVATION:])
    expected, *_ = plain.step(command + action * scale)
    assert np.array_equal(after[:N_OBSERVATION], expected)


def test_a_direct_policy_that_cannot_drive_ends_as_a_failed_episode_not_an_error():
    env = FigureEightEnv(plant="default")
    result = run_policy_episode(env, PolicyController(_policy("direct", N_OBSERVATION), env), seed=0)
    assert result.status != "completed"
    assert np.isfinite(result.J)


def test_the_episode_command_runs_a_policy_file(tmp_path, capsys):
    path = tmp_path / "zero.npz"
    _policy("residual", N_OBSERVATION + 2, out_weight=0.0).save(path)
    assert main(["episode", "--seed", "3", "--controller", f"policy:{path}", "--csv", str(tmp_path / "run.csv")]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["controller"] == f"policy:{path}"
    assert printed["J"] == run_episode(Theta(), FigureEightEnv(plant="default").episode_config, seed=3).J
    assert json.loads((tmp_path / "run.json").read_text())["metadata"]["controller"] == f"policy:{path}"
    assert (tmp_path / "run.csv").read_text().count("\n") > 500


def test_the_episode_command_writes_a_replay_with_the_mpc_beside_the_policy(tmp_path, capsys):
    path = tmp_path / "zero.npz"
    _policy("residual", N_OBSERVATION + 2, out_weight=0.0).save(path)
    page = tmp_path / "replay.html"
    assert main(["episode", "--seed", "3", "--controller", f"policy:{path}", "--html", str(page),
                 "--ghost", "default", "--ghost-theta", "k=0.07"]) == 0
    text = page.read_text()
    assert f"<h1>policy:{path} controller</h1>" in text  # the panel names what drove each car
    assert "beside it, the translucent car: default controller · completed · J " in text
    assert "k</td><td>0.05</td>" in text  # the first episode's theta, not the ghost's
    capsys.readouterr()
    assert main(["episode", "--ghost", "default"]) == 2
    assert "--ghost and --ghost-theta go with --html" in capsys.readouterr().err
