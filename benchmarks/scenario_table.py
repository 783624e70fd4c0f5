"""The scenarios beyond the paper's, untuned and tuned: any two radii, the edge of the drift window, several laps.

For each case: the untuned theta on N fresh seeds (`driftlab rescore`'s seeds), then the best theta of a job
(job default, seed 0) rescored on the same N seeds: completions and mean |e|. With --laps L: the untuned theta on
L laps, each seed's mean |e| per lap, and the worst ratio of the last lap's to the first's.

Run: OMP_NUM_THREADS=1 python benchmarks/scenario_table.py [--cases 25/44,30/44,36/52,44/44@0.35]
    [--iterations 150] [--samples 20] [--laps 3]
(a case is LEFT/RIGHT radii [m], optionally @SIDESLIP rad; ~1-2 min a case on 2 cores).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from driftlab.core.config import EpisodeConfig, Theta
from driftlab.core.configure import apply_overrides
from driftlab.core.episode import run_episode
from driftlab.core.robust import rescore_seeds


def _case_sets(case: str) -> dict[str, float]:
    radii, _, sideslip = case.partition("@")
    left, right = radii.split("/")
    sets = {"scenario.left_radius_m": float(left), "scenario.right_radius_m": float(right)}
    if sideslip:
        sets["scenario.sideslip_rad"] = float(sideslip)
    return sets


def _untuned(args):
    config, seed = args
    r = run_episode(Theta(), config, seed=seed)
    return r.completed, r.metrics.mean_abs_e_m, r.metrics.lap_mean_abs_e_m


def _untuned_runs(config, samples: int):
    with ProcessPoolExecutor(2) as pool:
        return list(pool.map(_untuned, [(config, int(s)) for s in rescore_seeds(samples)]))


def _cli(*args: str) -> dict:
    out = subprocess.run([sys.executable, "-m", "driftlab.cli", *args], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def _completed_text(runs) -> str:
    errors = [e for ok, e, _ in runs if ok]
    return f"{sum(ok for ok, _, _ in runs)}/{len(runs)}, {np.mean(errors) if errors else float('nan'):.2f} m"


def main() -> None:
    os.environ["OMP_NUM_THREADS"] = "1"
    parser = argparse.ArgumentParser()
    parser.add_argument("--cases", default="25/44,30/44,36/52,44/44@0.35")
    parser.add_argument("--iterations", type=int, default=150)
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--laps", type=int, default=3, help="the laps case (0: none)")
    args = parser.parse_args()
    db = os.path.join(tempfile.mkdtemp(), "scenarios.db")
    print(f"| case | untuned: completed, mean abs e | {args.iterations}-iteration job: best J | "
          f"tuned rescore: completed, mean abs e |")
    print("|---|---|---|---|")
    for case in [c for c in args.cases.split(",") if c]:
        sets = _case_sets(case)
        untuned = _untuned_runs(apply_overrides(EpisodeConfig(), sets), args.samples)
        name = f"case-{case}"
        set_args = [a for key, value in sets.items() for a in ("--set", f"{key}={value}")]
        tuned = _cli("tune", *set_args, "--iterations", str(args.iterations), "--seed", "0", "--name", name,
                     "--db", db, "--workers", "2")
        rescore = _cli("rescore", "--name", name, "--db", db, "--samples", str(args.samples))
        best = tuned["best"]
        print(f"| {case} | {_completed_text(untuned)} | {best['J']:.3f} ({best['status']}) | "
              f"{rescore['completed']}/{rescore['samples']}, {rescore['mean_abs_e_m'] or float('nan'):.2f} m |",
              flush=True)
    if args.laps:
        runs = _untuned_runs(apply_overrides(EpisodeConfig(), {"scenario.laps": args.laps}), args.samples)
        ratios = [laps[-1] / laps[0] for ok, _, laps in runs if ok]
        print(f"\n{args.laps} laps, untuned, default plant: {_completed_text(runs)}; last lap's mean abs e / first "
              f"lap's: median {np.median(ratios):.3f}, worst {max(ratios):.3f}")


if __name__ == "__main__":
    main()
