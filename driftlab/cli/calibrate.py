"""`driftlab calibrate`: a car's MPC weights found by DriftLab's optimizer at points of its drift window
(driftlab.services.calibration, the same run as ``POST /api/calibrations``), each point on its own (or all of them
together, ``--one-set``), stored as the car's profiles, of which a new job of that car takes the one for its drift
(driftlab.services.profiles), and written as a JSON file."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from typing import Any

from driftlab.cli.options import dask_address, db_url, finite, key_values, machine_cores, prune_rule
from driftlab.cli.shutdown import raise_if_terminated, stop_on_sigterm

SUMMARY_KEYS = ("profile_id", "plant_model", "vehicle_id", "score", "completed", "episodes", "per_point", "start",
                "candidates", "window", "weights", "wall_s")


def run_batch_on(executor):
    """A calibration's batches (driftlab.core.calibration.RunBatch) on a DriftLab executor, all in flight at once."""
    from driftlab.worker.calibrating import calibration_score

    def run(batch):
        raise_if_terminated()  # a SIGTERM lost in a finalizer stops the calibration at its next batch
        futures = [executor.submit(theta, doc, seed) for theta, doc, seed in batch]
        return [calibration_score(future.result()) for future in futures]
    return run


def _print_event(event: dict[str, Any]) -> None:
    """Messages as they come; the search's progress every 10th set or theta."""
    if "message" in event:
        sys.stderr.write(event["message"] + "\n")
    elif "progress" in event:
        p = event["progress"]
        n = p["tried"]
        if n % 10 and n != 1:
            return
        if p.get("step") == "theta":
            sys.stderr.write(f"[theta {n}] best score {p['best_score']:.3f}\n")
        else:
            sys.stderr.write(f"[{n}] best score {p['best_score']:.3f} ({p['best_completed']}/{p['best_episodes']} "
                             f"completed), last {p['last_score']:.3f} ({p['last_completed']}/{p['episodes']})\n")
    sys.stderr.flush()


def request_from_args(args: argparse.Namespace):
    from driftlab.core.calibration_request import CalibrationRequest
    from driftlab.core.config import Theta

    theta = key_values(args.theta.split(",") if args.theta else [], "--theta")
    return CalibrationRequest(
        plant=args.plant, sets=key_values(args.set or [], "--set"), points=args.points, iterations=args.iterations,
        seeds=args.seeds, seed=args.seed, rounds=args.rounds, one_set=args.one_set,
        theta={k: v for k, v in Theta.from_mapping(theta).as_dict().items() if k in theta},
        prune=prune_rule(args.prune).to_dict(),
        command="driftlab " + " ".join(shlex.quote(a) for a in args.argv))


def cmd_calibrate(args: argparse.Namespace) -> int:
    from driftlab.core.car_profile import profiles_file
    from driftlab.core.errors import ConfigError
    from driftlab.db import storage
    from driftlab.services.calibration import run_calibration
    from driftlab.worker.executors import open_executor

    request = request_from_args(args)
    try:
        request.validate()
    except ConfigError as exc:  # the request's own field names, as the CLI spells them
        raise ConfigError(str(exc).replace("one_set", "--one-set").replace("rounds:", "--rounds:")
                          .replace("points:", "--points:"), field=exc.field) from None
    stop_on_sigterm()
    factory = storage.open_database(db_url(args.db))
    address = dask_address(args)
    executor, _ = open_executor(args.workers or (None if address else machine_cores()), address)
    try:
        try:
            documents = run_calibration(request, factory, run_batch_on(executor), on_event=_print_event)
        except ConfigError as exc:
            raise ConfigError(str(exc).replace("points:", "--points:", 1), field=exc.field) from None
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM
        sys.stderr.write("\ncalibration stopped: the profiles of the points it finished are stored, the point in "
                         "progress is not\n")
        return 130
    finally:
        executor.shutdown()
        storage.close_database(factory)
    if args.out:  # the profiles as data; each calibration's log stays in the database (GET /api/profiles/{id})
        with open(args.out, "w") as handle:
            handle.write(profiles_file(finite(documents)))
    print(json.dumps(finite({"profiles": [{k: d[k] for k in SUMMARY_KEYS} for d in documents],
                             "wall_s": round(sum(d["wall_s"] for d in documents), 1)})))
    return 0


def add_calibrate_parser(sub, db_help: str, dask_help: str, int_in, plant_choices) -> argparse.ArgumentParser:
    cal = sub.add_parser("calibrate", help="find a car's MPC weights over points of its drift window; store them "
                         "as the car's profile (new jobs of that car take it)")
    cal.add_argument("--plant", choices=plant_choices, metavar="PLANT", required=True,
                     help="a plant preset: commonroad_std, commonroad_mb, or a plant installed beside DriftLab")
    cal.add_argument("--set", action="append", metavar="KEY=VALUE",
                     help="config override, e.g. plant.commonroad_vehicle=3, scenario.sideslip_rad=0.55")
    cal.add_argument("--points", help="SIDESLIP@RADIUS,... (default: the scenario's sideslip and every 0.05 rad "
                     "either side of it across the car's drift window on its circle, and its sideslip on circles "
                     "30/44 and 52/44 the size)")
    cal.add_argument("--iterations", type=int_in(1, 5000), default=150, metavar="N",
                     help="weight sets tried (1..5000, default 150)")
    cal.add_argument("--seeds", type=int_in(1, 64), default=3, metavar="N",
                     help="episode seeds per point (1..64, default 3)")
    cal.add_argument("--seed", type=int, default=0, help="the optimizer's seed")
    cal.add_argument("--workers", type=int_in(1, 1024), metavar="N",
                     help="episodes in flight (default: a local process per core this process may use, the "
                     "cluster's threads with --dask); the profiles found do not depend on it")
    cal.add_argument("--dask", metavar="ADDRESS", help=dask_help)
    cal.add_argument("--db", help=db_help)
    cal.add_argument("--theta", help="the theta every weight set drives, c_lr=..,c_rl=..,dV=..,k=.. (any subset; "
                     "default: the untuned theta), e.g. the best theta a job learned at the point")
    cal.add_argument("--rounds", type=int_in(1, 5), default=1, metavar="N",
                     help="rounds per point (1..5, default 1; a point where no weight set completes the untuned "
                          "theta gets a second): each round after the first learns the theta a job "
                          "would learn there with the last round's weights, then searches the weights again for it, "
                          "a decade around the last round's")
    cal.add_argument("--prune", metavar="off|CONFIDENCE,MIN_SEEDS",
                     help="stop a weight set whose first seeds are worse than the best set's on the same seeds with "
                          "confidence (default: on, 0.95,2; off: every set runs every seed)")
    cal.add_argument("--one-set", action="store_true",
                     help="one weight set for all the points (default: each point searched on its own and stored as "
                          "a profile of its own, which the jobs at that drift take)")
    cal.add_argument("--out", help="also write the profiles to this JSON file")
    return cal
