"""`driftlab calibrate`: a car's MPC weights found by DriftLab's optimizer at points of its drift window
(driftlab.core.calibration), each point on its own (or all of them together, ``--one-set``), stored as the car's
profiles (driftlab.db.profiles), of which a new job of that car takes the one for its drift
(driftlab.services.profiles), and written as a JSON file."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from dataclasses import asdict, replace
from importlib.metadata import version
from typing import Any

from driftlab.cli.options import dask_address, db_url, episode_config, finite
from driftlab.core.calibration import CalibrationPoint, calibrate, default_points, split_drivable
from driftlab.core.config import Theta, apply_overrides, config_to_dict
from driftlab.core.drivability import drift_window
from driftlab.core.errors import ConfigError


def parse_points(text: str | None) -> list[CalibrationPoint] | None:
    """'0.45@44,0.5@30' -> points (sideslip rad @ radius m)."""
    if not text:
        return None
    points = []
    for item in text.split(","):
        beta, _, radius = item.partition("@")
        try:
            points.append(CalibrationPoint(abs(float(beta)), float(radius)))
        except ValueError:
            raise ConfigError(f"--points: {item.strip()!r} is not SIDESLIP@RADIUS (e.g. 0.5@44)") from None
    return points


def _run_batch(executor):
    def run(batch):
        futures = [executor.submit(theta, doc, seed) for theta, doc, seed in batch]
        out = []
        for future in futures:
            outcome = future.result()
            error = outcome.metrics.get("mean_abs_e_m")
            out.append((outcome.status, float(outcome.J), float(outcome.metrics.get("completed_fraction", 0.0)),
                        None if error is None else float(error)))
        return out
    return run


def _progress(calibration) -> None:
    n = len(calibration.tried)
    if n % 10 and n != 1:
        return
    best = calibration.best
    last = calibration.tried[-1]
    sys.stderr.write(f"[{n}] best score {best.score:.3f} ({best.completed}/{len(best.episodes)} completed), "
                     f"last {last.score:.3f} ({last.completed}/{len(last.episodes)})\n")
    sys.stderr.flush()


def _model_candidates(base, args) -> list[dict[str, Any]]:
    """The controller's models to calibrate: for a car with its own tyres (a CommonRoad car) both the paper's
    independent rear forces and the rear friction circle matched to the car's drive answer, unless ``--set``
    chose one; the weights are searched for each and the better model kept."""
    chosen = any(item.split("=", 1)[0].strip() == "plant.model_drive_coupling" for item in args.set or [])
    if not base.plant.plant_type.own_car or chosen:
        return [{}]
    return [{}, {"plant.model_drive_coupling": not base.plant.model_drive_coupling}]


def _calibrate_model(base, points, executor, args, known, theta) -> tuple[Any, list, list] | None:
    """One candidate model's search over ``points`` (None: none of them is inside its window)."""
    inside, outside = split_drivable(base, points)
    if not inside:
        return None
    calibration = calibrate(base, inside, _run_batch(executor), iterations=args.iterations, seeds=args.seeds,
                            seed=args.seed, known=[mpc for _, mpc in known], theta=theta,
                            on_progress=_progress)
    return calibration, inside, outside


def _theta(args: argparse.Namespace):
    from driftlab.cli.options import key_values

    return Theta.from_mapping(key_values(args.theta.split(",") if args.theta else [], "--theta"))


def _learned_theta(given, point, last: dict[str, Any], executor, args):
    """The theta a job at ``point`` would learn with the weights it would take now: the last round's, if they
    completed anything there, else the car's own (driftlab.services.profiles.profile_for)."""
    from driftlab.core.calibration import learn_theta, point_config

    record = last["per_point"][0]
    weights = last["weights"] if record["completed"] else {}
    config = point_config(given, point)
    coupling = last["plant"].get("model_drive_coupling", False)
    if record["completed"] and coupling != config.plant.model_drive_coupling:  # the model those weights were for
        config = apply_overrides(config, {"plant.model_drive_coupling": coupling})
    config = replace(config, mpc=replace(config.mpc, **weights))

    def progress(n: int, best: float | None) -> None:
        if n % 10 == 0 or n == 1:
            sys.stderr.write(f"[theta {n}] best score {best:.3f}\n")
    theta, score = learn_theta(config, _run_batch(executor), iterations=args.iterations, seeds=args.seeds,
                               seed=args.seed, on_progress=progress)
    sys.stderr.write(f"learned at {point.label()}: {theta.as_dict()} (score {score:.3f})\n")
    return theta


def _summary(result, points) -> dict[str, Any]:
    return {"weights": result.weights, "score": result.score, "completed": result.completed,
            "episodes": len(result.episodes), "per_point": result.per_point(points)}


def _groups(given, points: list[CalibrationPoint], one_set: bool) -> list[list[CalibrationPoint]]:
    """The searches to run: all the points together (``--one-set``), or each point on its own, from the scenario's
    own drift outwards, so that each search knows what the nearer ones found."""
    if one_set:
        return [points]
    from driftlab.services.profiles import drift_distance

    scenario = given.scenario
    return [[p] for p in sorted(points, key=lambda p: drift_distance(scenario.sideslip_rad, scenario.left_radius_m,
                                                                     asdict(p)))]


def _calibrate_group(given, points, executor, args, known, theta) -> dict[str, Any]:
    """The weights for ``points``, each candidate model searched and the better one kept: the profile's document."""
    candidates = []
    for change in _model_candidates(given, args):
        try:
            base = apply_overrides(given, change) if change else given
        except ConfigError as exc:  # this model has no fit at the scenario's drift: the other candidates run
            sys.stderr.write(f"skipped the model with {change}: {exc}\n")
            continue
        sys.stderr.write(f"calibrating {', '.join(p.label() for p in points)} with plant.model_drive_coupling="
                         f"{str(base.plant.model_drive_coupling).lower()}\n")
        found = _calibrate_model(base, points, executor, args, known, theta)
        if found is not None:
            candidates.append((base, *found))
    if not candidates:
        raise ConfigError(f"--points: no candidate model drifts at {', '.join(p.label() for p in points)}")
    base, calibration, inside, outside = min(candidates, key=lambda c: (c[1].best.score, -c[1].best.completed))
    best, start = calibration.best, calibration.tried[0]
    radii = sorted({p.radius_m for p, _ in inside})
    window = [drift_window(config, config.scenario.left_radius_m, 0.2, 1.0).as_dict()
              for config in (next(c for p, c in inside if p.radius_m == r) for r in radii)]
    return {
        "plant_model": base.plant.model, "vehicle_id": base.plant.commonroad_vehicle,
        "plant": config_to_dict(base)["plant"], "mpc": {**config_to_dict(base)["mpc"], **best.weights},
        **_summary(best, calibration.points), "start": _summary(start, calibration.points),
        "candidates": [{"model_drive_coupling": b.plant.model_drive_coupling, **_summary(c.best, c.points)}
                       for b, c, _, _ in candidates],
        "known": [{"from": label, **_summary(result, calibration.points)}
                  for (label, _), result in zip(known, calibration.known_results(), strict=True) if result],
        "points": [asdict(p) for p in calibration.points],
        "skipped": [{**asdict(p), "reason": reason} for p, reason in outside],
        "window": window, "seeds": calibration.seeds, "iterations": args.iterations,
        "theta": "untuned" if theta == Theta() else theta.as_dict(),
        "command": "driftlab " + " ".join(shlex.quote(a) for a in args.argv), "driftlab_version": version("driftlab")}


SUMMARY_KEYS = ("profile_id", "plant_model", "vehicle_id", "score", "completed", "episodes", "per_point", "start",
                "candidates", "window", "weights", "wall_s")


def cmd_calibrate(args: argparse.Namespace) -> int:
    from driftlab.db import profiles, storage
    from driftlab.services.profiles import known_weight_sets
    from driftlab.worker.executors import open_executor

    given = episode_config(args)
    _theta(args)  # a bad --theta is refused before anything runs
    if args.rounds > 1 and args.one_set:
        raise ConfigError("--rounds: a round learns a theta at one point; with --one-set there are several (use "
                          "--rounds 1)")
    points = parse_points(args.points) or default_points(given)
    inside, outside = split_drivable(given, points)
    for point, reason in outside:
        sys.stderr.write(f"skipped {point.label()}: {reason}\n")
    if not inside:
        raise ConfigError("--points: none of the points is inside the car's drift window (`driftlab equilibrium "
                          f"--window --plant {args.plant}` prints it)")
    factory = storage.open_database(db_url(args.db))
    with storage.transaction(factory) as session:
        known = known_weight_sets(session, given.mpc)
    executor, _ = open_executor(args.workers, dask_address(args))
    documents = []
    try:
        for group in _groups(given, [p for p, _ in inside], args.one_set):
            sys.stderr.write(f"after the car's own weights, {len(known)} weight sets known to drive other cars or "
                             f"drifts: {'; '.join(label for label, _ in known)}\n")
            theta = _theta(args)
            for round_number in range(1, args.rounds + 1):
                started = time.perf_counter()
                if round_number > 1:
                    theta = _learned_theta(given, group[0], documents[-1], executor, args)
                document = _calibrate_group(given, group, executor, args, known, theta)
                document["skipped"] += [{**asdict(p), "reason": reason} for p, reason in outside]
                document["round"] = round_number
                document["wall_s"] = round(time.perf_counter() - started, 1)
                with storage.transaction(factory) as session:
                    profile = profiles.add_profile(session, plant_model=document["plant_model"],
                                                   vehicle_id=document["vehicle_id"], document=document)
                    documents.append({"profile_id": profile.id, **document})
                found = replace(given.mpc, **document["weights"])
                if found != given.mpc and all(found != mpc for _, mpc in known):
                    points_text = ", ".join(CalibrationPoint(**p).label() for p in document["points"])
                    known = [(f"profile {profile.id} ({points_text})", found), *known]
    finally:
        executor.shutdown()
        storage.close_database(factory)
    if args.out:
        with open(args.out, "w") as handle:
            json.dump(finite({"profiles": documents}), handle, indent=1)
    print(json.dumps(finite({"profiles": [{k: d[k] for k in SUMMARY_KEYS} for d in documents],
                             "wall_s": round(sum(d["wall_s"] for d in documents), 1)})))
    return 0


def add_calibrate_parser(sub, db_help: str, dask_help: str, int_in, plant_choices) -> argparse.ArgumentParser:
    cal = sub.add_parser("calibrate", help="find a car's MPC weights over points of its drift window; store them "
                         "as the car's profile (new jobs of that car take it)")
    cal.add_argument("--plant", choices=plant_choices, required=True)
    cal.add_argument("--set", action="append", metavar="KEY=VALUE",
                     help="config override, e.g. plant.commonroad_vehicle=3, scenario.sideslip_rad=0.55")
    cal.add_argument("--points", help="SIDESLIP@RADIUS,... (default: the scenario's sideslip and 0.05 rad either "
                     "side of it on its radius, and its sideslip on circles 30/44 and 52/44 the size)")
    cal.add_argument("--iterations", type=int_in(1, 5000), default=150, metavar="N",
                     help="weight sets tried (1..5000, default 150)")
    cal.add_argument("--seeds", type=int_in(1, 64), default=3, metavar="N",
                     help="episode seeds per point (1..64, default 3)")
    cal.add_argument("--seed", type=int, default=0, help="the optimizer's seed")
    cal.add_argument("--workers", type=int_in(1, 1024), metavar="N",
                     help="episodes in flight (default: 1 local process, the cluster's threads with --dask)")
    cal.add_argument("--dask", metavar="ADDRESS", help=dask_help)
    cal.add_argument("--db", help=db_help)
    cal.add_argument("--theta", help="the theta every weight set drives, c_lr=..,c_rl=..,dV=..,k=.. (any subset; "
                     "default: the untuned theta), e.g. the best theta a job learned at the point")
    cal.add_argument("--rounds", type=int_in(1, 5), default=1, metavar="N",
                     help="rounds per point (1..5, default 1): each round after the first learns the theta a job "
                          "would learn there with the last round's weights, then searches the weights again for it")
    cal.add_argument("--one-set", action="store_true",
                     help="one weight set for all the points (default: each point searched on its own and stored as "
                          "a profile of its own, which the jobs at that drift take)")
    cal.add_argument("--out", help="also write the profiles to this JSON file")
    return cal
