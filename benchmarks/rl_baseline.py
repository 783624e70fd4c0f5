"""A learned policy beside the tuned MPC on the same plant and seeds (docs/rl_baseline.md).

Trains Stable-Baselines3's SAC on DriftLab's environment (driftlab.gym), either alone (``--variant sac``: the policy
sends the commands) or on top of the MPC (``--variant residual``: the policy adds a bounded correction to the MPC's
command), for a wall-time budget; exports the policy as a NumPy file (driftlab.gym.policy) that `driftlab episode
--controller policy:FILE` runs; and scores it, with DriftLab's own metrics, on 20 fresh seeds. ``--variant mpc``
tunes the MPC as a job of the job default does (``--iterations`` evaluations) and scores its best theta on the same
seeds.

Run (the rl extra: the environment and Stable-Baselines3; PyTorch's CPU build first, docs/rl_baseline.md):
    pip install torch --index-url https://download.pytorch.org/whl/cpu && pip install -e ".[rl]"
    OMP_NUM_THREADS=1 python benchmarks/rl_baseline.py --variant sac --minutes 60 --out results/sac_default
    OMP_NUM_THREADS=1 python benchmarks/rl_baseline.py --variant mpc --iterations 150 --out results/mpc_default
Add ``--plant commonroad_std`` for CommonRoad's BMW (0.5 rad on 44 m circles). The learning curves of runs:
``python benchmarks/rl_baseline.py curves OUT.png RUN_FOLDER...``. Each run writes
``summary.json`` (the table's row), ``curve.csv`` (the learning curve: environment steps, wall seconds, episodes,
the last 20 training episodes' completion and return) and, for a policy, ``policy.npz``.

Training reward: the environment's reward (minus the paper's stage cost) plus a bonus for each step the car is
still on the 8. Without it, every step's reward is negative and ending the episode early (a spin) is what pays
best. The bonus is the 95th percentile of the stage costs the MPC itself meets on the normalisation episodes, so that
staying on the 8 as well as the MPC does pays. It is measured from the plant, not set by hand. Observations are
scaled by the mean and spread of the same MPC episodes' observations, and the policy file records the scaling.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

EVAL_SEEDS = 20
NORMALISATION_SEEDS = 5


def env_of(args: argparse.Namespace, theta: dict[str, float] | None = None):
    from driftlab.gym import FigureEightEnv

    return FigureEightEnv(plant=args.plant, controller="default", config=dict(kv.split("=", 1) for kv in args.set),
                          theta=theta)


def fresh_seeds() -> list[int]:
    """The seeds a rescore scores on: never a job's or a calibration's (driftlab.core.robust.rescore_seeds)."""
    from driftlab.core.robust import rescore_seeds

    return list(rescore_seeds(EVAL_SEEDS))


def row_of(results: list[Any]) -> dict[str, Any]:
    """DriftLab's metrics of a controller over the evaluation seeds: completion, mean |e| and the flick's max |e|
    (over completed episodes), mean J."""
    done = [r for r in results if r.status == "completed"]
    summaries = [r.summary() for r in done]

    def flick_max(summary: dict[str, Any]) -> float:
        return max((p["max_abs_e_m"] for p in summary["phases"] if p["phase"].startswith("inertia")), default=np.nan)

    return {"completion": f"{len(done)}/{len(results)}",
            "completion_rate": len(done) / len(results),
            "mean_abs_e_m": statistics.fmean(s["mean_abs_e_m"] for s in summaries) if done else None,
            "flick_max_abs_e_m": statistics.fmean(flick_max(s) for s in summaries) if done else None,
            "J_mean": statistics.fmean(r.J for r in results),
            "statuses": {s: sum(r.status == s for r in results) for s in sorted({r.status for r in results})}}


def normalisation(args: argparse.Namespace, residual: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """Observation mean and spread, and the alive bonus, from the MPC's own episodes on seeds the evaluation never
    uses."""
    from driftlab.gym import mpc_policy

    env = env_of(args)
    policy = mpc_policy(env)
    observations, costs = [], []
    for seed in range(NORMALISATION_SEEDS):
        observation, info = env.reset(seed=10_000 + seed)
        costs.append(info["stage_cost"])
        while True:
            action = policy(observation)
            observations.append(np.concatenate([observation, action]) if residual else observation)
            observation, reward, terminated, truncated, _ = env.step(action)
            costs.append(-reward)
            if terminated or truncated:
                break
    stacked = np.array(observations)
    std = stacked.std(axis=0)
    return stacked.mean(axis=0), np.where(std > 1e-6, std, 1.0), float(np.percentile(costs, 95))


def train(args: argparse.Namespace) -> dict[str, Any]:
    import gymnasium as gym
    import torch
    from stable_baselines3 import SAC
    from stable_baselines3.common.callbacks import BaseCallback

    from driftlab.gym.policy import (
        MlpPolicy,
        PolicyController,
        ResidualMpcEnv,
        residual_scale_of,
        run_policy_episode,
    )

    torch.set_num_threads(1)
    residual = args.variant == "residual"
    obs_mean, obs_std, bonus = normalisation(args, residual)

    class Shaped(gym.Wrapper):
        """Scaled observations, and the alive bonus added to each step's reward (training only)."""

        def __init__(self, env: gym.Env) -> None:
            super().__init__(env)
            self.observation_space = gym.spaces.Box(-np.inf, np.inf, obs_mean.shape, dtype=np.float32)

        def reset(self, **kwargs: Any):
            observation, info = self.env.reset(**kwargs)
            return ((observation - obs_mean) / obs_std).astype(np.float32), info

        def step(self, action: Any):
            observation, reward, terminated, truncated, info = self.env.step(action)
            alive = 0.0 if terminated and info.get("status") != "completed" else bonus
            return ((observation - obs_mean) / obs_std).astype(np.float32), reward + alive, terminated, truncated, info

    base = env_of(args)
    scale = residual_scale_of(base, args.residual_share) if residual else np.zeros(2)
    env = Shaped(ResidualMpcEnv(base, scale) if residual else base)
    env.reset(seed=args.seed)  # the training episodes' seeds come from the environment's generator, seeded here
    curve: list[dict[str, Any]] = []
    started = time.perf_counter()
    deadline = started + 60.0 * args.minutes

    class Recorder(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.episodes: list[tuple[bool, float]] = []
            self.episode_return = 0.0

        def _on_step(self) -> bool:
            self.episode_return += float(self.locals["rewards"][0])
            if self.locals["dones"][0]:
                status = self.locals["infos"][0].get("status")
                self.episodes.append((status == "completed", self.episode_return))
                self.episode_return = 0.0
                last = self.episodes[-20:]
                curve.append({"steps": self.num_timesteps, "wall_s": round(time.perf_counter() - started, 1),
                              "episodes": len(self.episodes),
                              "completion_last20": sum(c for c, _ in last) / len(last),
                              "return_last20": statistics.fmean(r for _, r in last)})
            return time.perf_counter() < deadline and self.num_timesteps < args.max_steps

    model = SAC("MlpPolicy", env, seed=args.seed, verbose=0, device="cpu", learning_starts=args.learning_starts)
    recorder = Recorder()
    model.learn(total_timesteps=args.max_steps, callback=recorder)
    train_s = time.perf_counter() - started

    actor = model.policy.actor
    linears = [m for m in actor.latent_pi if isinstance(m, torch.nn.Linear)] + [actor.mu]
    policy = MlpPolicy(mode="residual" if residual else "direct",
                       weights=tuple(m.weight.detach().double().numpy().copy() for m in linears),
                       biases=tuple(m.bias.detach().double().numpy().copy() for m in linears),
                       obs_mean=obs_mean, obs_std=obs_std, residual_scale=scale,
                       trained_on={"plant": args.plant, "set": args.set, "variant": args.variant,
                                   "command": " ".join(sys.argv), "steps": model.num_timesteps,
                                   "minutes": args.minutes, "seed": args.seed, "alive_bonus": bonus})
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "policy.npz")
    policy.save(path)
    policy = MlpPolicy.load(path)  # scored as `driftlab episode --controller policy:FILE` runs it
    scored_env = env_of(args)
    controller = PolicyController(policy, scored_env)
    results = [run_policy_episode(scored_env, controller, seed) for seed in fresh_seeds()]
    with open(os.path.join(args.out, "curve.csv"), "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=["steps", "wall_s", "episodes", "completion_last20",
                                                    "return_last20"])
        writer.writeheader()
        writer.writerows(curve)
    return {**row_of(results), "variant": args.variant, "plant": args.plant, "set": args.set,
            "train_minutes": round(train_s / 60.0, 1), "env_steps": model.num_timesteps,
            "episodes_used": len(recorder.episodes), "alive_bonus": bonus, "policy": path}


def tune_mpc(args: argparse.Namespace) -> dict[str, Any]:
    """The job default (`driftlab tune`) for ``--iterations`` evaluations, its best theta on the evaluation seeds
    (``--iterations 0``: the untuned theta, no episode used)."""
    from driftlab.core.config import Theta
    from driftlab.core.tuning import TuningSpec
    from driftlab.db import storage
    from driftlab.gym import episode_config

    theta, episodes, tune_s = Theta().as_dict(), 0, 0.0
    with tempfile.TemporaryDirectory() as folder:
        if args.iterations == 0:  # the environment's config: the preset and --set, fitted
            config = episode_config(args.plant, "default", dict(kv.split("=", 1) for kv in args.set))
            return _mpc_row(args, theta, config, episodes, tune_s)
        url = f"sqlite:///{folder}/mpc.db"
        command = [sys.executable, "-m", "driftlab.cli", "tune", "--name", "mpc", "--db", url, "--iterations",
                   str(args.iterations), "--seed", str(args.seed), "--plant", args.plant,
                   *[item for kv in args.set for item in ("--set", kv)]]
        started = time.perf_counter()
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
        tune_s = time.perf_counter() - started
        factory = storage.open_database(url)
        with storage.snapshot(factory) as session:
            job = storage.get_job_by_name(session, name="mpc")
            best = storage.best_evaluation(session, job_id=job.id)
            episodes = sum(len(e.seeds or []) for e in storage.evaluations(session, job_id=job.id))
            theta = dict(best.theta)
            # the job's own config: with the car's calibrated profile where one ships (`driftlab tune` applies it)
            config = TuningSpec.from_dict(job.spec).config
        storage.close_database(factory)
    return _mpc_row(args, theta, config, episodes, tune_s)


def _mpc_row(args: argparse.Namespace, theta: dict[str, float], config: Any, episodes: int,
             tune_s: float) -> dict[str, Any]:
    from driftlab.core.config import Theta
    from driftlab.core.episode import run_episode

    results = [run_episode(Theta.from_mapping(theta), config, seed=seed) for seed in fresh_seeds()]
    return {**row_of(results), "variant": "mpc", "plant": args.plant, "set": args.set, "theta": theta,
            "train_minutes": round(tune_s / 60.0, 1), "episodes_used": episodes, "iterations": args.iterations}


def plot_curves(folders: list[str], png: str) -> None:
    """The learning curves of runs (their ``curve.csv``): completion of the last 20 training episodes against
    environment steps, one line a run, with what the run's ``summary.json`` says it is."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(7.5, 3.6))
    for folder in folders:
        with open(os.path.join(folder, "summary.json")) as handle:
            summary = json.load(handle)
        with open(os.path.join(folder, "curve.csv")) as handle:
            rows = list(csv.DictReader(handle))
        axis.plot([int(r["steps"]) for r in rows], [float(r["completion_last20"]) for r in rows],
                  label=f"{summary['variant']}, {summary['plant']} ({summary['train_minutes']} min)")
    axis.set_xlabel("environment steps")
    axis.set_ylabel("completed, last 20 training episodes")
    axis.set_ylim(-0.05, 1.05)
    axis.grid(alpha=0.3)
    axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(png, dpi=110)


def main() -> None:
    if sys.argv[1:2] == ["curves"]:  # python benchmarks/rl_baseline.py curves OUT.png RUN_FOLDER...
        plot_curves(sys.argv[3:], sys.argv[2])
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variant", choices=("sac", "residual", "mpc"), required=True)
    parser.add_argument("--plant", default="default")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--minutes", type=float, default=60.0, help="training wall-time budget (sac, residual)")
    parser.add_argument("--max-steps", type=int, default=5_000_000, help="training step budget (sac, residual)")
    parser.add_argument("--learning-starts", type=int, default=5_000, help="random steps before SAC learns")
    parser.add_argument("--residual-share", type=float, default=0.2,
                        help="residual: the correction's reach, a share of each command's half-range")
    parser.add_argument("--iterations", type=int, default=150, help="mpc: the job's evaluations")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    row = tune_mpc(args) if args.variant == "mpc" else train(args)
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "summary.json"), "w") as handle:
        json.dump(row, handle, indent=1)
    print(json.dumps(row))


if __name__ == "__main__":
    main()
