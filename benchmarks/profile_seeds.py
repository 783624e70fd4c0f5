"""Each profile of a `driftlab calibrate --out` file on fresh seeds at its point: its weights, controller model and
steering limit, driving its theta (the untuned one unless a round learned one), on the calibration's verification
block of seeds (the first 10 are those its own check ran). Prints one line a profile and the total completed.

Run: OMP_NUM_THREADS=1 python benchmarks/profile_seeds.py PROFILES.json [--seeds 20] [--workers 2]
(needs the commonroad extra; ~20 s for ten STD profiles on 2 cores).
"""

import argparse
import json

from driftlab.cli.calibrate import run_batch_on
from driftlab.core.calibration import CalibrationPoint, point_config, verify
from driftlab.core.config import Theta
from driftlab.core.configure import apply_overrides, preset_config
from driftlab.worker.executors import open_executor


def profile_config(profile: dict):
    """The car of ``profile`` with its weights, steering limit and controller model."""
    return apply_overrides(preset_config(profile["plant_model"]), {
        "plant.commonroad_vehicle": profile["vehicle_id"],
        "plant.model_drive_coupling": profile["plant"]["model_drive_coupling"],
        "mpc.steer_limit_rad": profile["mpc"]["steer_limit_rad"],
        **{f"mpc.{name}": value for name, value in profile["weights"].items()}})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("profiles", help="a `driftlab calibrate --out` file")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    with open(args.profiles) as handle:
        profiles = json.load(handle)["profiles"]
    executor, _ = open_executor(args.workers, None)
    run = run_batch_on(executor)
    total = 0
    try:
        for profile in profiles:
            record = profile["per_point"][0]
            point = CalibrationPoint(record["sideslip_rad"], record["radius_m"])
            theta = None if profile["theta"] == "untuned" else Theta.from_mapping(profile["theta"])
            checked, = verify([(point, point_config(profile_config(profile), point))], profile["weights"], run,
                              theta=theta, seeds=args.seeds)
            total += checked["completed"]
            error = checked["mean_abs_e_m"]
            print(f"{point.label()}: {checked['completed']}/{args.seeds} completed"
                  + (f", mean |e| {error:.3f} m" if error is not None else ""), flush=True)
    finally:
        executor.shutdown()
    print(f"total {total} of {args.seeds * len(profiles)}")


if __name__ == "__main__":
    main()
