"""Random search over the default controller's settings for a wide mismatch envelope (how the offset-free
defaults of MpcConfig were chosen): each setting drives the untuned theta on a *training* set of plants, one
change at a time from the default or the nominal plant, at values other than those of the envelope grid
(benchmarks/envelope.py), so that the grid stays a held-out test. Ranked by plants completed, then mean J.

Run: OMP_NUM_THREADS=1 python benchmarks/tune_envelope.py [N_SETS=160] [--base key=value ...]
         [--around '{"mpc.q_speed": 3.4, ...}']   (two processes; --around: a local search near those settings)
"""

import argparse
import json
import os
from multiprocessing import Pool

import numpy as np

from driftlab.core.config import Theta
from driftlab.core.configure import apply_overrides, preset_config
from driftlab.core.episode import run_episode

TRAINING = [("default", {})] + [("default", {f"plant.{k}": v}) for k, values in (
    ("friction_scale", (0.97, 1.02, 1.08)), ("tyre_c_scale", (1.15, 1.25, 1.35)), ("mass_scale", (0.95, 1.05)),
    ("yaw_inertia_scale", (0.75, 0.9, 1.1)), ("steer_lag_s", (0.04, 0.065, 0.09)), ("cg_height_m", (0.35, 0.5)))
    for v in values]
TRAINING += [("nominal", {})] + [("nominal", {f"plant.{k}": v}) for k, values in (
    ("friction_scale", (0.88, 0.95, 1.05, 1.15)), ("tyre_c_scale", (0.95, 1.05, 1.15, 1.25)), ("mass_scale", (0.95,)),
    ("steer_lag_s", (0.03, 0.065))) for v in values]

MAX_CHATTER_RAD = 0.02


def sample(rng: np.random.Generator) -> dict:
    return {"mpc.q_sideslip": 10 ** rng.uniform(2.5, 3.7), "mpc.q_yaw_rate": 10 ** rng.uniform(0, 2.5),
            "mpc.q_steer": 10 ** rng.uniform(-1, 2), "mpc.q_drive_kn": 10 ** rng.uniform(-2, 0.5),
            "mpc.r_steer_step": 10 ** rng.uniform(0, 2.5), "mpc.r_drive_step_kn": 10 ** rng.uniform(-3, 0),
            "mpc.steer_rate_radps": rng.uniform(4, 10), "mpc.q_speed": 10 ** rng.uniform(0.3, 1.7),
            "mpc.q_lateral_error": 10 ** rng.uniform(-1.5, 1.5), "mpc.q_course_error": 10 ** rng.uniform(-1, 2),
            "mpc.disturbance_gain": 10 ** rng.uniform(-1.7, -0.8), "mpc.estimator_hold_s": rng.uniform(0.3, 2.0),
            "mpc.model_steer_lag_s": rng.uniform(0.015, 0.06), "mpc.feedback_in_model": True,
            "mpc.disturbance_start_gain": rng.uniform(0.03, 0.3)}


def steer_chatter_rad(result) -> float:
    """Mean |change of the steering command| per control step in the sustained drifts [rad]: a controller
    whose model expects more actuator lag than the plant has rings at half the control rate."""
    phase, steer = result.column("phase"), result.column("delta_cmd_rad")
    sustained = np.isin(phase, (0, 2, 4))
    both = sustained[1:] & sustained[:-1]
    return float(np.mean(np.abs(np.diff(steer))[both])) if both.any() else 0.0


def perturb(rng: np.random.Generator, center: dict) -> dict:
    """A neighbour of ``center``: each positive number scaled by 10^U(-0.3, 0.3), booleans kept."""
    return {k: v if isinstance(v, bool) else float(v) * 10 ** rng.uniform(-0.3, 0.3) for k, v in center.items()}


def evaluate(args):
    i, base_overrides, center, seed_base = args
    rng = np.random.default_rng(seed_base + i)
    settings = {**(perturb(rng, center) if center and i > 0 else center or sample(rng)), **base_overrides}
    results = []
    for plant, change in TRAINING:
        config = apply_overrides(preset_config(plant=plant), {**settings, **change})
        results.append(run_episode(Theta(), config, seed=0))
    # A run that rings (over MAX_CHATTER_RAD per step) does not count as completed, however it scores.
    good = [r.completed and steer_chatter_rad(r) <= MAX_CHATTER_RAD for r in results]
    return sum(good), float(np.mean([r.J for r in results])), settings


def main() -> None:
    os.environ["OMP_NUM_THREADS"] = "1"
    parser = argparse.ArgumentParser()
    parser.add_argument("n_sets", type=int, nargs="?", default=160)
    parser.add_argument("--base", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--seed", type=int, default=9000, help="the settings drawn are those of seeds SEED + i")
    parser.add_argument("--around", type=json.loads, default=None, metavar="JSON",
                        help="search the neighbourhood of these settings (the first set is the centre itself)")
    args = parser.parse_args()
    base = dict(item.split("=", 1) for item in args.base)
    with Pool(2) as pool:
        out = pool.map(evaluate, [(i, base, args.around, args.seed) for i in range(args.n_sets)], chunksize=2)
    out.sort(key=lambda o: (-o[0], o[1]))
    print(f"{len(TRAINING)} training plants")
    for completed, mean_j, settings in out[:10]:
        print(completed, round(mean_j, 3), json.dumps({k: (round(v, 4) if isinstance(v, float) else v)
                                                       for k, v in settings.items()}))


if __name__ == "__main__":
    main()
