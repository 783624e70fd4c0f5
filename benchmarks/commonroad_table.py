"""CommonRoad plants, untuned and tuned: for each (vehicle, sideslip) the untuned theta and the best theta of a
150-iteration job (job default, seed 0), both on 40 fresh seeds (`driftlab rescore`): completions and mean |e|.

Run: OMP_NUM_THREADS=1 python benchmarks/commonroad_table.py [--cases 2:0.45,2:0.5,2:0.55,3:0.6] [--iterations 150]
    [--plant commonroad_std|commonroad_mb] [--job-seeds 0,1,2,3] [--jitter 20]
(needs the commonroad extra; ~1 min a case and job seed on 2 cores). --jitter N: N draws of the tuned theta moved
by up to +-1% of each bound's width, each on N fresh seeds / 5 (a basin, not a point: how many complete).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from driftlab.core.config import Theta
from driftlab.core.configure import apply_overrides, preset_config
from driftlab.core.drivability import drivable_reason
from driftlab.core.episode import run_episode
from driftlab.core.errors import ConfigError
from driftlab.core.robust import rescore_seeds


def _untuned(args):
    config, seed = args
    r = run_episode(Theta(), config, seed=seed)
    return r.completed, r.metrics.as_dict().get("mean_abs_e_m")


def _jittered(args):
    config, theta, seed = args
    return run_episode(theta, config, seed=seed).completed


def _jitter(config, best_theta: dict, bounds: dict, draws: int, samples: int) -> tuple[int, int]:
    """(completed, episodes) of ``draws`` thetas within +-1% of the bound widths around ``best_theta``."""
    rng = np.random.default_rng(0)
    seeds = rescore_seeds(samples)
    jobs = []
    for i in range(draws):
        moved = {k: v + 0.01 * (bounds[k][1] - bounds[k][0]) * rng.uniform(-1, 1) for k, v in best_theta.items()}
        jobs += [(config, Theta.from_mapping(moved), int(seeds[(i * 4 + j) % len(seeds)])) for j in range(4)]
    with ProcessPoolExecutor(2) as pool:
        done = list(pool.map(_jittered, jobs))
    return sum(done), len(done)


def _cli(*args: str) -> dict:
    out = subprocess.run([sys.executable, "-m", "driftlab.cli", *args], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def main() -> None:
    os.environ["OMP_NUM_THREADS"] = "1"
    parser = argparse.ArgumentParser()
    parser.add_argument("--cases", default="2:0.45,2:0.5,2:0.55,3:0.6")
    parser.add_argument("--iterations", type=int, default=150)
    parser.add_argument("--samples", type=int, default=40)
    parser.add_argument("--plant", default="commonroad_std", choices=("commonroad_std", "commonroad_mb"))
    parser.add_argument("--job-seeds", default="0", help="comma-separated job seeds, each a job of its own")
    parser.add_argument("--jitter", type=int, default=0, help="draws around each tuned theta (0: none)")
    args = parser.parse_args()
    db = os.path.join(tempfile.mkdtemp(), "commonroad.db")
    print("| vehicle | sideslip | untuned: completed, mean abs e | job seed | tuned J | tuned rescore: completed, "
          "mean abs e | jitter: completed |")
    print("|---|---|---|---|---|---|---|")
    for case in args.cases.split(","):
        vehicle, beta = case.split(":")
        sets = [f"plant.commonroad_vehicle={vehicle}", f"scenario.sideslip_rad={beta}"]
        try:
            config = apply_overrides(preset_config(args.plant),
                                     {"plant.commonroad_vehicle": int(vehicle), "scenario.sideslip_rad": float(beta)})
        except ConfigError as exc:
            print(f"| {vehicle} | {beta} | refused: {exc} | | | | |")
            continue
        if drivable_reason(config):
            print(f"| {vehicle} | {beta} | not drivable: {drivable_reason(config)} | | | | |")
            continue
        with ProcessPoolExecutor(2) as pool:
            untuned = list(pool.map(_untuned, [(config, s) for s in rescore_seeds(args.samples)]))
        errors = [e for ok, e in untuned if ok]
        untuned_text = (f"{sum(ok for ok, _ in untuned)}/{args.samples}, "
                        f"{np.mean(errors) if errors else float('nan'):.2f} m")
        set_args = [a for s in sets for a in ("--set", s)]
        for job_seed in args.job_seeds.split(","):
            name = f"cr{vehicle}-{beta}-{job_seed}"
            tuned = _cli("tune", "--plant", args.plant, *set_args, "--iterations", str(args.iterations),
                         "--seed", job_seed, "--name", name, "--db", db, "--workers", "2")
            rescore = _cli("rescore", "--name", name, "--db", db, "--samples", str(args.samples))
            best = tuned["best"]
            jitter = ""
            if args.jitter and best["status"] == "completed":
                from driftlab.core.tuning import TuningSpec

                bounds = TuningSpec.from_dict(tuned_spec(db, name)).bounds
                done, total = _jitter(config, best["theta"], bounds, args.jitter, args.samples)
                jitter = f"{done}/{total}"
            print(f"| {vehicle} | {beta} | {untuned_text} | {job_seed} | {best['J']:.3f} ({best['status']}) | "
                  f"{rescore['completed']}/{rescore['samples']}, {rescore['mean_abs_e_m'] or float('nan'):.2f} m | "
                  f"{jitter} |", flush=True)


def tuned_spec(db: str, name: str) -> dict:
    """The stored job's spec (its bounds)."""
    from driftlab.db import storage

    factory = storage.open_database(f"sqlite:///{db}")
    with storage.snapshot(factory) as session:
        return storage.find_job(session, name=name).spec

if __name__ == "__main__":
    main()
