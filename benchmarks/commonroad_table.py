"""CommonRoad plants, untuned and tuned: for each (vehicle, sideslip) the untuned theta and the best theta of a
150-iteration job (job default, seed 0), both on 40 fresh seeds (`driftlab rescore`): completions and mean |e|.

Run: OMP_NUM_THREADS=1 python benchmarks/commonroad_table.py [--cases 2:0.45,2:0.5,2:0.55,3:0.6] [--iterations 150]
(needs the commonroad extra; ~1 min a case on 2 cores)
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from driftlab.core.config import EpisodeConfig, Theta, apply_overrides
from driftlab.core.drivability import drivable_reason
from driftlab.core.episode import run_episode
from driftlab.core.errors import ConfigError
from driftlab.core.robust import rescore_seeds


def _untuned(args):
    config, seed = args
    r = run_episode(Theta(), config, seed=seed)
    return r.completed, r.metrics.as_dict().get("mean_abs_e_m")


def _cli(*args: str) -> dict:
    out = subprocess.run([sys.executable, "-m", "driftlab.cli", *args], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def main() -> None:
    os.environ["OMP_NUM_THREADS"] = "1"
    parser = argparse.ArgumentParser()
    parser.add_argument("--cases", default="2:0.45,2:0.5,2:0.55,3:0.6")
    parser.add_argument("--iterations", type=int, default=150)
    parser.add_argument("--samples", type=int, default=40)
    args = parser.parse_args()
    db = os.path.join(tempfile.mkdtemp(), "commonroad.db")
    print("| vehicle | sideslip | untuned: completed, mean abs e | tuned J | tuned rescore: completed, mean abs e |")
    print("|---|---|---|---|---|")
    for case in args.cases.split(","):
        vehicle, beta = case.split(":")
        sets = [f"plant.commonroad_vehicle={vehicle}", f"scenario.sideslip_rad={beta}"]
        try:
            config = apply_overrides(EpisodeConfig.preset("commonroad_std"),
                                     {"plant.commonroad_vehicle": int(vehicle), "scenario.sideslip_rad": float(beta)})
        except ConfigError as exc:
            print(f"| {vehicle} | {beta} | refused: {exc} | | |")
            continue
        if drivable_reason(config):
            print(f"| {vehicle} | {beta} | not drivable: {drivable_reason(config)} | | |")
            continue
        with ProcessPoolExecutor(2) as pool:
            untuned = list(pool.map(_untuned, [(config, s) for s in rescore_seeds(args.samples)]))
        errors = [e for ok, e in untuned if ok]
        name = f"cr{vehicle}-{beta}"
        set_args = [a for s in sets for a in ("--set", s)]
        tuned = _cli("tune", "--plant", "commonroad_std", *set_args, "--iterations", str(args.iterations),
                     "--name", name, "--db", db, "--workers", "2")
        rescore = _cli("rescore", "--name", name, "--db", db, "--samples", str(args.samples))
        best = tuned["best"]
        print(f"| {vehicle} | {beta} | {sum(ok for ok, _ in untuned)}/{args.samples}, "
              f"{np.mean(errors) if errors else float('nan'):.2f} m | {best['J']:.3f} ({best['status']}) | "
              f"{rescore['completed']}/{rescore['samples']}, {rescore['mean_abs_e_m'] or float('nan'):.2f} m |",
              flush=True)


if __name__ == "__main__":
    main()
