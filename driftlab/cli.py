"""The `driftlab` command line: an edge over core/ (parsing, JSON output, files)."""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from typing import Any

from driftlab.core.config import EpisodeConfig, Theta, apply_overrides
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.errors import ConfigError, NoEquilibriumError
from driftlab.core.vehicle import pack_params


class _Parser(argparse.ArgumentParser):
    """argparse that reports bad arguments on one line with exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(f"driftlab: error: {message}\n")
        sys.exit(2)


def _finite(value: Any) -> Any:
    """JSON has no NaN: non-finite numbers become null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, list):
        return [_finite(v) for v in value]
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    return value


def _key_values(items: list[str], what: str) -> dict[str, str]:
    pairs = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"{what} expects key=value, got {item!r}")
        pairs[key.strip()] = value.strip()
    return pairs


def _config(args: argparse.Namespace) -> EpisodeConfig:
    preset = EpisodeConfig.preset(args.plant or "default", getattr(args, "controller", "default"))
    return apply_overrides(preset, _key_values(args.set or [], "--set"))


def _cmd_equilibrium(args: argparse.Namespace) -> int:
    config = _config(args)
    try:
        eq = drift_equilibrium(args.radius, args.beta, pack_params(config.vehicle))
    except NoEquilibriumError as exc:
        sys.stderr.write(f"driftlab: error: {exc}\n")
        return 2
    out: dict[str, Any] = eq.as_dict()
    if args.plant:
        try:
            plant_eq = drift_equilibrium(args.radius, args.beta, config.plant.packed_params(config.vehicle))
            out["plant"] = plant_eq.as_dict()
            out["plant"]["mismatch"] = {"dV": plant_eq.speed_mps - eq.speed_mps,
                                        "ddelta": plant_eq.steer_rad - eq.steer_rad,
                                        "dFxr": plant_eq.drive_force_n - eq.drive_force_n}
        except NoEquilibriumError as exc:
            out["plant"] = {"error": str(exc)}
    print(json.dumps(out))
    return 0


def _cmd_episode(args: argparse.Namespace) -> int:
    from driftlab.core.episode import COLUMNS, run_episode
    from driftlab.core.track import FigureEight

    config = _config(args)
    theta = Theta.from_mapping(_key_values(args.theta.split(",") if args.theta else [], "--theta"))
    result = run_episode(theta, config)
    print(json.dumps(_finite(result.summary())))
    if args.csv:
        with open(args.csv, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(COLUMNS)
            writer.writerows(result.trajectory.tolist())
    if args.plot:
        from driftlab.plotting import plot_episode

        scenario = config.scenario
        plot_episode(result, FigureEight(scenario.left_radius_m, scenario.right_radius_m), args.plot,
                     title=f"{args.plant} plant, {args.controller} controller\ntheta {theta.as_dict()}\n"
                           f"{result.status}, J = {result.J:.3f}")
    return 0


def _tuning_spec(args: argparse.Namespace):
    from driftlab.core.tuning import TuningSpec

    config = apply_overrides(EpisodeConfig(), _key_values(args.set or [], "--set"))
    bounds = {}
    for item in args.bound or []:
        name, _, pair = item.partition("=")
        lo, _, hi = pair.partition(":")
        bounds[name.strip()] = [lo, hi]
    return TuningSpec(iterations=args.iterations, seed_points=args.seed_points, active_set=args.active_set,
                      seed=args.seed, bounds=bounds, config=config)


def _cmd_tune(args: argparse.Namespace) -> int:
    from driftlab.db import storage
    from driftlab.worker.executor import LocalProcessExecutor
    from driftlab.worker.job_loop import Progress, run_job

    spec = _tuning_spec(args)
    factory = storage.open_database(storage.database_url(args.db))
    with storage.transaction(factory) as session:
        job = storage.find_job(session, name=args.name) if args.name else None
        if job is None:
            name = args.name or storage.unique_job_name(session, "tune")
            job = storage.create_job(session, name=name, spec=spec.to_dict(), seed=spec.seed)
            sys.stderr.write(f"job {job.name} (id {job.id}): {spec.iterations} iterations\n")
        else:
            done = storage.count_evaluations(session, job_id=job.id)
            sys.stderr.write(f"resuming job {job.name} (id {job.id}) at {done} of {job.spec['iterations']}\n")
        job_id, name = job.id, job.name

    def progress(p: Progress) -> None:
        best = f"{p.best_J:.3f}" if p.best_J is not None else "-"
        eta = f"{p.eta_s:.0f} s" if p.eta_s is not None else "-"
        line = f"[{p.n_done}/{p.iterations}] best J {best}  last {p.last.status} J {p.last.J:.3f}  ETA {eta}"
        if sys.stderr.isatty():
            sys.stderr.write(f"\r{line}    ")
        elif p.n_done % 25 == 0 or p.n_done == p.iterations:  # logs: a line now and then, not a blob
            sys.stderr.write(line + "\n")
        sys.stderr.flush()

    executor = LocalProcessExecutor(args.workers)
    started = time.perf_counter()
    try:
        status = run_job(factory, job_id, executor, workers=args.workers, on_progress=progress)
    finally:
        executor.shutdown()
    with storage.transaction(factory) as session:
        best = storage.best_evaluation(session, job_id=job_id)
        out = {"job": name, "id": job_id, "status": status, "wall_s": round(time.perf_counter() - started, 2),
               "n_done": storage.count_evaluations(session, job_id=job_id),
               "best": None if best is None else {"index": best.index, "theta": best.theta, "J": best.J,
                                                   "status": best.status}}
    sys.stderr.write("\n")
    print(json.dumps(out))
    return 0 if status != "failed" else 1


def _cmd_report(args: argparse.Namespace) -> int:
    from driftlab.report import write_report

    path = write_report(db_url=_db_url(args.db), name=args.name, out_dir=args.out, baseline_samples=args.baselines)
    print(json.dumps({"report": str(path)}))
    return 0


def _cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from driftlab.server.app import create_app

    app = create_app(_db_url(args.db), workers=args.workers)
    shown_host = "localhost" if args.host == "0.0.0.0" else args.host
    print(f"DriftLab: the 3D view on http://{shown_host}:{args.port}/viser/, the API docs on "
          f"http://{shown_host}:{args.port}/docs", flush=True)
    uvicorn.run(app, host=args.host, port=args.port, log_level="info")
    return 0


def _db_url(db: str | None) -> str:
    from driftlab.db.storage import database_url

    return database_url(db)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="driftlab", description="Learning-based inertia drift (Zhou et al. 2025).")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    eq = sub.add_parser("equilibrium", help="drift equilibrium of the model (and a plant) at radius and beta")
    eq.add_argument("--radius", type=float, default=44.0, help="path radius R [m]")
    eq.add_argument("--beta", type=float, default=-0.4, help="sideslip [rad]; < 0 left-hand drift")
    eq.add_argument("--plant", choices=("default", "nominal"), help="also solve this plant's own equilibrium")
    eq.add_argument("--set", action="append", metavar="KEY=VALUE", help="config override, e.g. plant.cg_height_m=0.3")
    eq.set_defaults(func=_cmd_equilibrium)
    ep = sub.add_parser("episode", help="run one 30 s figure-8 episode and print its metrics as JSON")
    ep.add_argument("--theta", help="c_lr=..,c_rl=..,dV=..,k=.. (defaults: 0.02, 0.02, 0, 0.05)")
    ep.add_argument("--plant", choices=("default", "nominal"), default="default")
    ep.add_argument("--controller", choices=("default", "paper"), default="default",
                    help="default: DriftLab's MPC with path states and actuator lags; paper: the paper's MPC")
    ep.add_argument("--set", action="append", metavar="KEY=VALUE", help="config override, e.g. mpc.q_sideslip=400")
    ep.add_argument("--csv", help="write the trajectory to this CSV file")
    ep.add_argument("--plot", help="write the paper's figures to this PNG file")
    ep.set_defaults(func=_cmd_episode)
    tu = sub.add_parser("tune", help="run (or resume) a Bayesian-optimization tuning job headless")
    tu.add_argument("--iterations", type=int, default=500)
    tu.add_argument("--seed-points", type=int, default=20)
    tu.add_argument("--active-set", type=int, default=400)
    tu.add_argument("--seed", type=int, default=0)
    tu.add_argument("--db", help="SQLite file or SQLAlchemy URL (default: ./driftlab.db or DRIFTLAB_DATABASE_URL)")
    tu.add_argument("--name", help="job name; an existing name resumes that job")
    tu.add_argument("--set", action="append", metavar="KEY=VALUE", help="config override, e.g. plant.steer_lag_s=0.02")
    tu.add_argument("--bound", action="append", metavar="NAME=LO:HI", help="theta bound, e.g. k=0:0.1")
    tu.add_argument("--workers", type=int, default=1, choices=range(1, 65), metavar="N",
                    help="episodes evaluated at once (1..64)")
    tu.set_defaults(func=_cmd_tune)
    sv = sub.add_parser("serve", help="the dashboard and REST API (http://127.0.0.1:8000)")
    sv.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1: this machine only)")
    sv.add_argument("--port", type=int, default=8000)
    sv.add_argument("--db", help="SQLite file or SQLAlchemy URL (default: ./driftlab.db or DRIFTLAB_DATABASE_URL)")
    sv.add_argument("--workers", type=int, default=2, choices=range(1, 65), metavar="N",
                    help="episode processes (1..64)")
    sv.set_defaults(func=_cmd_serve)
    rp = sub.add_parser("report", help="write the paper's results for a tuning job")
    rp.add_argument("--name", required=True)
    rp.add_argument("--db")
    rp.add_argument("--out", required=True, help="output directory")
    rp.add_argument("--baselines", type=int, help="random samples for the random-search baseline "
                    "(default: as many as the job's evaluations)")
    rp.set_defaults(func=_cmd_report)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ConfigError, LookupError) as exc:  # bad input, or no such job / evaluation
        sys.stderr.write(f"driftlab: error: {exc}\n")
        return 2


if __name__ == "__main__":
    sys.exit(main())
