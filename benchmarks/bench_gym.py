"""Steps per second of the Gymnasium environment (driftlab.gym) on the default plant: random actions within the
action space, and the MPC's own commands (driftlab.gym.mpc_policy); resets included where an episode ends, as in
training. Median of 5 repetitions, CPU time of this one process (one core; the wall clock beside it).

Run: OMP_NUM_THREADS=1 python benchmarks/bench_gym.py [--steps N] [--plant NAME] [--wrapped] [--profile]
"""

import argparse
import cProfile
import pstats
import statistics
import time

import gymnasium as gym
import numpy as np

from driftlab.gym import ENV_ID, mpc_policy


def random_steps(env, n_steps: int, rng: np.random.Generator) -> int:
    """``n_steps`` steps of uniform random actions in the box (drawn beforehand: the sampling is not the env's)."""
    low, high = env.action_space.low, env.action_space.high
    actions = [[float(a), float(b)] for a, b in rng.uniform(low, high, size=(n_steps, 2))]
    env.reset(seed=int(rng.integers(0, 2**31)))
    episodes = 1
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset(seed=int(rng.integers(0, 2**31)))
            episodes += 1
    return episodes


def mpc_steps(env, n_steps: int, rng: np.random.Generator) -> int:
    policy = mpc_policy(env)
    observation, _ = env.reset(seed=int(rng.integers(0, 2**31)))
    episodes = 1
    for _ in range(n_steps):
        observation, _, terminated, truncated, _ = env.step(policy(observation))
        if terminated or truncated:
            observation, _ = env.reset(seed=int(rng.integers(0, 2**31)))
            episodes += 1
    return episodes


def measure(name: str, run, env, n_steps: int, repetitions: int = 5) -> None:
    run(env, 200, np.random.default_rng(0))  # load the compiled kernels
    cpu, wall, episodes = [], [], []
    for repetition in range(repetitions):
        rng = np.random.default_rng(repetition + 1)
        c0, w0 = time.process_time(), time.perf_counter()
        episodes.append(run(env, n_steps, rng))
        cpu.append(n_steps / (time.process_time() - c0))
        wall.append(n_steps / (time.perf_counter() - w0))
    print(f"{name:7s} {statistics.median(cpu):9,.0f} steps/s CPU (median of {repetitions}, {n_steps} steps each, "
          f"{statistics.median(episodes)} episodes), {statistics.median(wall):9,.0f} steps/s wall")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--plant", default="default")
    parser.add_argument("--wrapped", action="store_true", help="through gym.make's wrappers (default: unwrapped)")
    parser.add_argument("--profile", action="store_true", help="cProfile one repetition of random steps")
    parser.add_argument("--sort", default="tottime", help="the profile's order (tottime, cumulative)")
    args = parser.parse_args()
    made = gym.make(ENV_ID, plant=args.plant)
    env = made if args.wrapped else made.unwrapped
    print(f"plant={args.plant} {'gym.make wrappers' if args.wrapped else 'unwrapped'}")
    if args.profile:
        random_steps(env, 200, np.random.default_rng(0))
        profile = cProfile.Profile()
        profile.runcall(random_steps, env, args.steps, np.random.default_rng(1))
        pstats.Stats(profile).sort_stats(args.sort).print_stats(25)
        return
    measure("random", random_steps, env, args.steps)
    measure("mpc", mpc_steps, env, max(args.steps // 4, 1000))


if __name__ == "__main__":
    main()
