"""The paper experiment (500 iterations, 20 seed points, active set 400, 2 workers) on the default plant, with
robust evaluation (the default: 4 seeded episodes per evaluation, a would-be best confirmed on 4 more) and
without (one episode, no confirmation), for several BO seeds; each learned theta is then rescored under fresh
seeds.

Run: OMP_NUM_THREADS=1 python benchmarks/robust_vs_plain.py [--seeds 0 1 2] [--iterations 500]
     [--rescore 40] [--db /tmp/robust_vs_plain.db]
Prints one JSON line per job and a table: best J, wall time, rescore completion.
"""

import argparse
import json
import os
import subprocess
import sys
import time


def _cli(*args: str) -> dict:
    out = subprocess.run([sys.executable, "-m", "driftlab.cli", *args], capture_output=True, text=True,
                         env={**os.environ, "OMP_NUM_THREADS": "1"})
    if out.returncode != 0:
        raise SystemExit(out.stderr)
    return json.loads(out.stdout)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--iterations", type=int, default=500)
    parser.add_argument("--rescore", type=int, default=40)
    parser.add_argument("--variants", nargs="+", default=["4:4", "1:0"],
                        help="robust_samples:confirm_samples per job (default: robust 4:4, plain 1:0)")
    parser.add_argument("--db", default="/tmp/robust_vs_plain.db")
    args = parser.parse_args()
    rows = []
    for seed in args.seeds:
        for variant in args.variants:
            samples, confirm = variant.split(":")
            name = f"paper{args.iterations}-s{seed}-r{samples}c{confirm}"
            started = time.perf_counter()
            tuned = _cli("tune", "--iterations", str(args.iterations), "--workers", "2", "--seed", str(seed),
                         "--robust-samples", samples, "--confirm-samples", confirm, "--name", name, "--db", args.db)
            wall = time.perf_counter() - started
            rescored = _cli("rescore", "--name", name, "--db", args.db, "--samples", str(args.rescore))
            row = {"job": name, "seed": seed, "robust_samples": int(samples), "confirm_samples": int(confirm),
                   "best_J": tuned["best"]["J"],
                   "best_status": tuned["best"]["status"], "theta": tuned["best"]["theta"],
                   "tune_wall_s": round(wall, 1), "rescore_completed": rescored["completed"],
                   "rescore_samples": rescored["samples"], "rescore_J_mean": rescored["J_mean"],
                   "rescore_J_mean_completed": rescored["J_mean_completed"]}
            rows.append(row)
            print(json.dumps(row), flush=True)
    print("| job | robust + confirm samples | best J (tuning) | tune wall s | rescore completed | rescore J mean |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['job']} | {r['robust_samples']} + {r['confirm_samples']} | {r['best_J']:.3f} | "
              f"{r['tune_wall_s']} | {r['rescore_completed']}/{r['rescore_samples']} | {r['rescore_J_mean']:.3f} |")


if __name__ == "__main__":
    main()
