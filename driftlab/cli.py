"""The `driftlab` command line: an edge over core/ (parsing, JSON output, files)."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from typing import Any

from driftlab.core.config import PLANT_PRESETS, EpisodeConfig, Theta, apply_overrides, config_to_dict
from driftlab.core.drivability import check_drivable
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.errors import ConfigError, NoEquilibriumError
from driftlab.core.robust import MAX_ROBUST_SAMPLES
from driftlab.core.tuning import DEFAULT_CONFIRM_SAMPLES, DEFAULT_ROBUST_SAMPLES
from driftlab.core.vehicle import pack_params
from driftlab.shutdown import stop_on_sigterm

DB_HELP = ("SQLite file or SQLAlchemy URL (default: DRIFTLAB_DATABASE_URL, else the shared "
           "~/.local/share/driftlab/driftlab.db)")


def _int_in(lo: int, hi: int):
    """An argparse type: an integer in [lo, hi], with a one-line error naming the range."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer in [{lo}, {hi}], got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be an integer in [{lo}, {hi}], got {value}")
        return value
    return parse


DASK_HELP = ("run episodes on this Dask scheduler, e.g. tcp://HOST:8786 (default: DRIFTLAB_DASK_ADDRESS, else a "
             "local process pool)")


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


PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def _check_output_file(option: str, path: str | None) -> None:
    """A file we may write: not a folder, in a folder that exists."""
    if not path:
        return
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise ConfigError(f"{option} {path}: is a folder; give a file name")
    if not os.path.isdir(folder):
        raise ConfigError(f"{option} {path}: the folder {folder} does not exist")


def _key_values(items: list[str], what: str) -> dict[str, str]:
    pairs = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"{what} expects key=value, got {item!r}")
        if key.strip() in pairs:
            raise ConfigError(f"{what} sets {key.strip()!r} twice")
        pairs[key.strip()] = value.strip()
    return pairs


PLANT_CHOICES = tuple(PLANT_PRESETS)


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
    if args.plant and config.plant.model != "driftlab":
        from driftlab.core.commonroad.family import family_summary

        plant = family_summary(config.plant, args.radius, args.beta)
        if "V" in plant:
            plant["mismatch"] = {"dV": plant["V"] - eq.speed_mps, "ddelta": plant["delta"] - eq.steer_rad,
                                 "dFxr": plant["drive_n"] - eq.drive_force_n}
        out["plant"] = plant
    elif args.plant:
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
    for option, path in (("--csv", args.csv), ("--plot", args.plot)):  # before the episode runs, not after
        _check_output_file(option, path)
    if args.plot and os.path.splitext(args.plot)[1].lower() not in PLOT_SUFFIXES:
        raise ConfigError(f"--plot {args.plot}: the file name must end in one of {', '.join(PLOT_SUFFIXES)}")
    check_drivable(config)
    result = run_episode(theta, config, seed=args.seed)
    print(json.dumps(_finite(result.summary())))
    if args.csv:
        from driftlab.export import trajectory_csv

        metadata = {"theta": theta.as_dict(), "seed": args.seed, "J_episode": result.J, "episode_status": result.status,
                    "J": result.J, "status": result.status, "n_seeds": 1, "config": config_to_dict(config)}
        with open(args.csv, "w", newline="") as handle:
            handle.write(trajectory_csv(list(COLUMNS), result.trajectory, metadata))
    if args.plot:
        from driftlab.plotting import plot_episode

        scenario = config.scenario
        plot_episode(result, FigureEight(scenario.left_radius_m, scenario.right_radius_m), args.plot,
                     title=f"{args.plant} plant, {args.controller} controller, seed {args.seed}\n"
                           f"theta {theta.as_dict()}\n{result.status}, J = {result.J:.3f}")
    return 0


def _tuning_spec(args: argparse.Namespace):
    from driftlab.core.tuning import TuningSpec

    config = _config(args)
    check_drivable(config)
    bounds = {}
    for item in args.bound or []:
        name, _, pair = item.partition("=")
        lo, _, hi = pair.partition(":")
        bounds[name.strip()] = [lo, hi]
    from driftlab.core.tuning import DEFAULT_SEED_POINTS, PAPER_PRESET

    preset = PAPER_PRESET if args.preset == "paper" else {"iterations": 500, "seed_points": DEFAULT_SEED_POINTS,
                                                          "active_set": 400, "model_correction": True}
    iterations = preset["iterations"] if args.iterations is None else args.iterations
    seed_points = preset["seed_points"] if args.seed_points is None else args.seed_points
    active_set = preset["active_set"] if args.active_set is None else args.active_set
    correction = preset["model_correction"] if args.model_correction is None else args.model_correction == "on"
    return TuningSpec(iterations=iterations, seed_points=seed_points, active_set=active_set,
                      seed=args.seed, robust_samples=args.robust_samples, confirm_samples=args.confirm_samples,
                      bounds=bounds, config=config, model_correction=correction,
                      deterministic=bool(args.deterministic))


def _open_tuning_job(factory, args: argparse.Namespace, runner: str) -> tuple[int, str]:
    """Create the job, or take up the stored one of that name (its settings win; a given --iterations extends
    it); then claim its lease. A job another live runner holds is refused (LeaseHeld: exit 2)."""
    from driftlab.db import lifecycle, storage
    from driftlab.db.lifecycle import JobStatus

    with storage.transaction(factory) as session:
        job = storage.find_job(session, name=args.name) if args.name else None
        if job is None:
            spec = _tuning_spec(args)
            name = args.name or storage.unique_job_name(session, "tune")
            job = storage.create_job(session, name=name, spec=spec.to_dict(), seed=spec.seed)
            message = f"job {job.name} (id {job.id}): {spec.iterations} iterations"
        else:
            if lifecycle.lease_is_live(job):  # refuse before changing anything
                lifecycle.claim(session, job_id=job.id, runner=runner)
            if args.iterations is not None and args.iterations != job.spec["iterations"]:
                lifecycle.extend(session, job_id=job.id, iterations=args.iterations)
            done = storage.count_evaluations(session, job_id=job.id)
            message = f"resuming job {job.name} (id {job.id}) at {done} of {job.spec['iterations']}"
        job_id, name, status = job.id, job.name, job.status
    if status != JobStatus.FINISHED:
        with storage.transaction(factory) as session:
            lifecycle.claim(session, job_id=job_id, runner=runner,
                            from_statuses=(JobStatus.QUEUED, JobStatus.PAUSED, JobStatus.FAILED))
    sys.stderr.write(message + "\n")
    return job_id, name


def _cmd_tune(args: argparse.Namespace) -> int:
    from driftlab.core.compiled import episode_kernels_cached
    from driftlab.db import lifecycle, storage
    from driftlab.worker.executor import open_executor
    from driftlab.worker.job_loop import Progress, run_job

    stop_on_sigterm()
    factory = storage.open_database(_db_url(args.db))
    runner = lifecycle.new_runner_id("tune")
    job_id, name = _open_tuning_job(factory, args, runner)

    def progress(p: Progress) -> None:
        best = f"{p.best_J:.3f}" if p.best_J is not None else "-"
        eta = f"{p.eta_s:.0f} s" if p.eta_s is not None else "-"
        line = f"[{p.n_done}/{p.iterations}] best J {best}  last {p.last.status} J {p.last.J:.3f}  ETA {eta}"
        if sys.stderr.isatty():
            sys.stderr.write(f"\r{line}    ")
        elif p.n_done % 25 == 0 or p.n_done == p.iterations:  # logs: a line now and then, not a blob
            sys.stderr.write(line + "\n")
        sys.stderr.flush()

    started = time.perf_counter()
    with storage.transaction(factory) as session:
        status = storage.get_job(session, job_id=job_id).status
    if status == lifecycle.JobStatus.RUNNING and episode_kernels_cached() is False:
        sys.stderr.write("compiling the simulation (numba, once after an install); the first evaluation follows\n")
    if status == lifecycle.JobStatus.RUNNING:  # ours now
        executor, workers = open_executor(args.workers, _dask_address(args))
        try:
            status = run_job(factory, job_id, executor, runner=runner, workers=workers, on_progress=progress)
        except KeyboardInterrupt:
            with storage.transaction(factory) as session:
                lifecycle.release(session, job_id=job_id, runner=runner, status=lifecycle.JobStatus.PAUSED)
            sys.stderr.write(f"\njob {name} paused; run the same command to continue\n")
            return 130
        finally:
            executor.shutdown()
    with storage.transaction(factory) as session:
        error = storage.get_job(session, job_id=job_id).error
        if status == lifecycle.JobStatus.PAUSED and error:
            sys.stderr.write(f"\ndriftlab: job {name} paused: {error}; run the same command to continue\n")
        best = storage.best_evaluation(session, job_id=job_id)
        out = {"job": name, "id": job_id, "status": str(status), "wall_s": round(time.perf_counter() - started, 2),
               "n_done": storage.count_evaluations(session, job_id=job_id),
               "best": storage.best_summary(best)}
    sys.stderr.write("\n")
    print(json.dumps(out))
    return 0 if status != "failed" else 1


def _cmd_rescore(args: argparse.Namespace) -> int:
    from driftlab.worker.scoring import rescore_job

    print(json.dumps(_finite(rescore_job(db_url=_db_url(args.db), name=args.name, samples=args.samples,
                                         workers=args.workers, dask_address=_dask_address(args)))))
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from driftlab.report import write_report

    if os.path.exists(args.out) and not os.path.isdir(args.out):
        raise ConfigError(f"--out {args.out}: is a file; give a folder (created if missing)")
    if args.study:
        from driftlab.study_report import write_study_report

        print(json.dumps({"report": str(write_study_report(db_url=_db_url(args.db), name=args.study,
                                                           out_dir=args.out))}))
        return 0
    path = write_report(db_url=_db_url(args.db), name=args.name, out_dir=args.out, baseline_samples=args.baselines,
                        rescore_samples=args.rescore_samples, dask_address=_dask_address(args))
    print(json.dumps({"report": str(path)}))
    return 0


def _cmd_study(args: argparse.Namespace) -> int:
    from driftlab.study_command import cmd_study

    dask = _dask_address(args) if hasattr(args, "dask") else None
    return cmd_study(args, _tuning_spec, _db_url(args.db), dask)


def _cmd_serve(args: argparse.Namespace) -> int:
    import socket

    import uvicorn

    from driftlab.server.app import create_app
    from driftlab.settings import Settings

    settings = Settings()
    if args.host not in ("127.0.0.1", "localhost", "::1") and not settings.token:
        # Reachable from other machines: every client there could start, pause and delete jobs.
        raise ConfigError(f"--host {args.host}: serving beyond this machine needs DRIFTLAB_TOKEN (mutations then "
                          "need 'Authorization: Bearer <token>', the view /viser/?token=<token>); or bind 127.0.0.1")
    # Bind before touching any job: a second server on a taken port must leave the first one's jobs alone.
    family = socket.AF_INET6 if ":" in args.host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((args.host, args.port))
    except OSError as exc:
        sock.close()
        raise ConfigError(f"--port {args.port} on {args.host}: {exc.strerror or exc}") from None
    sock.listen(2048)
    sock.set_inheritable(True)
    if args.dask:
        settings = settings.model_copy(update={"dask_address": args.dask})
    workers = args.workers or (None if settings.dask_address else 2)
    app = create_app(_db_url(args.db), workers=workers, settings=settings)
    shown_host = "localhost" if args.host == "0.0.0.0" else args.host
    login = "?token=<DRIFTLAB_TOKEN>" if settings.token else ""
    print(f"DriftLab: the 3D view on http://{shown_host}:{args.port}/viser/{login}, the API docs on "
          f"http://{shown_host}:{args.port}/docs", flush=True)
    server = uvicorn.Server(uvicorn.Config(app, log_level="info"))
    server.run(sockets=[sock])
    return 0


def _dask_address(args: argparse.Namespace) -> str | None:
    from driftlab.settings import Settings

    return args.dask or Settings().dask_address


def _db_url(db: str | None) -> str:
    from driftlab.settings import database_url

    return database_url(db)


def _add_job_options(parser: argparse.ArgumentParser) -> None:
    """The options of a tuning job's specification (shared by `tune` and `study seeds`), but its seed."""
    parser.add_argument("--iterations", type=int, help="evaluations in total (default 500 for a new job); on a "
                        "stored job a new budget: a finished job continues to it")
    parser.add_argument("--preset", choices=("default", "paper"), default="default",
                        help="paper: the paper's BO, 500 iterations, 20 space-filling points, active set 400, "
                             "theta's four parameters only (default: 12 space-filling points, model correction on); "
                             "options given explicitly win")
    parser.add_argument("--model-correction", choices=("on", "off"),
                        help="also learn the controller model's friction and tyre-C scales (theta.model_mu_scale, "
                             "theta.model_c_scale); default on, off with --preset paper")
    parser.add_argument("--deterministic", action="store_true", default=None,
                        help="one evaluation at a time (its seeds still in parallel): the thetas depend on the seed "
                             "and settings only, not on the number of workers or which episode finishes first")
    parser.add_argument("--seed-points", type=int, help="space-filling evaluations before the GP (default 12)")
    parser.add_argument("--active-set", type=int, help="most evaluations the GP is fit on (default 400)")
    parser.add_argument("--robust-samples", type=int, default=DEFAULT_ROBUST_SAMPLES, metavar="N",
                        help=f"seeded episodes per evaluation, 1..{MAX_ROBUST_SAMPLES} (default "
                             f"{DEFAULT_ROBUST_SAMPLES}): J is their mean and an evaluation completes only if all "
                             "of them do")
    parser.add_argument("--confirm-samples", type=int, default=DEFAULT_CONFIRM_SAMPLES, metavar="N",
                        help=f"more seeds an evaluation must also complete before it counts as the best so far "
                             f"(0..64, default {DEFAULT_CONFIRM_SAMPLES}; 0: off)")
    parser.add_argument("--plant", choices=PLANT_CHOICES, default="default",
                        help="the plant preset the --set overrides start from (commonroad_std: CommonRoad's STD, "
                             "vehicle 2, sideslip 0.5, needs the commonroad extra)")
    parser.add_argument("--controller", choices=("default", "paper"), default="default")
    parser.add_argument("--set", action="append", metavar="KEY=VALUE",
                        help="config override, e.g. plant.steer_lag_s=0.02")
    parser.add_argument("--bound", action="append", metavar="NAME=LO:HI", help="theta bound, e.g. k=0:0.1 or "
                        "model_c_scale=0.9:1.2")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="driftlab", description="Learning-based inertia drift (Zhou et al. 2025).")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    eq = sub.add_parser("equilibrium", help="drift equilibrium of the model (and a plant) at radius and beta")
    eq.add_argument("--radius", type=float, default=44.0, help="path radius R [m]")
    eq.add_argument("--beta", type=float, default=-0.4, help="sideslip [rad]; < 0 left-hand drift")
    eq.add_argument("--plant", choices=PLANT_CHOICES, help="also solve this plant's own equilibrium (for a CommonRoad "
                    "plant its drift family: every steady drift, and whether the main one countersteers)")
    eq.add_argument("--set", action="append", metavar="KEY=VALUE", help="config override, e.g. plant.cg_height_m=0.3")
    eq.set_defaults(func=_cmd_equilibrium)
    ep = sub.add_parser("episode", help="run one 30 s figure-8 episode and print its metrics as JSON")
    ep.add_argument("--theta", help="c_lr=..,c_rl=..,dV=..,k=..,model_mu_scale=..,model_c_scale=.. (any subset; "
                    "defaults: 0.02, 0.02, 0, 0.05, 1, 1)")
    ep.add_argument("--plant", choices=PLANT_CHOICES, default="default")
    ep.add_argument("--controller", choices=("default", "paper"), default="default",
                    help="default: DriftLab's MPC with path states and actuator lags; paper: the paper's MPC")
    ep.add_argument("--set", action="append", metavar="KEY=VALUE", help="config override, e.g. mpc.q_sideslip=400")
    ep.add_argument("--seed", type=int, default=0, help="episode seed: the plant's per-episode variation, start and "
                    "sensor noise (default 0; the nominal plant has none)")
    ep.add_argument("--csv", help="write the trajectory to this CSV file")
    ep.add_argument("--plot", help="write the paper's figures to this PNG file")
    ep.set_defaults(func=_cmd_episode)
    tu = sub.add_parser("tune", help="run (or resume) a Bayesian-optimization tuning job headless")
    _add_job_options(tu)
    tu.add_argument("--seed", type=int, default=0, help="optimizer seed; also picks the episode seeds")
    tu.add_argument("--db", help=DB_HELP)
    tu.add_argument("--name", help="job name; an existing name resumes that job")
    tu.add_argument("--dask", metavar="ADDRESS", help=DASK_HELP)
    tu.add_argument("--workers", type=_int_in(1, 1024), metavar="N",
                    help="episodes in flight at once, 1..1024 (default: 1 locally, the cluster's threads with --dask)")
    tu.set_defaults(func=_cmd_tune)
    sv = sub.add_parser("serve", help="the dashboard and REST API (http://127.0.0.1:8000)")
    sv.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1: this machine only)")
    sv.add_argument("--port", type=_int_in(1, 65535), default=8000, metavar="PORT",
                    help="TCP port, 1..65535 (default 8000)")
    sv.add_argument("--db", help=DB_HELP)
    sv.add_argument("--dask", metavar="ADDRESS", help=DASK_HELP)
    sv.add_argument("--workers", type=_int_in(1, 1024), metavar="N",
                    help="episodes in flight at once, 1..1024 (default: 2 local processes, the cluster's threads "
                         "with --dask)")
    sv.set_defaults(func=_cmd_serve)
    rs = sub.add_parser("rescore", help="run a job's best theta, exactly as stored, under fresh seeds; print JSON")
    rs.add_argument("--name", required=True)
    rs.add_argument("--db", help=DB_HELP)
    rs.add_argument("--samples", type=_int_in(1, 1000), default=30, metavar="N",
                    help="episodes, each with a seed never used in tuning (1..1000, default 30)")
    rs.add_argument("--workers", type=_int_in(1, 1024), metavar="N",
                    help="episodes in flight, 1..1024 (default: 2 local processes, the cluster's threads with --dask)")
    rs.add_argument("--dask", metavar="ADDRESS", help=DASK_HELP)
    rs.set_defaults(func=_cmd_rescore)
    from driftlab.study_command import add_study_parser

    st = add_study_parser(sub, DB_HELP, DASK_HELP, _int_in, _add_job_options)
    st.set_defaults(func=_cmd_study, seed=0)
    rp = sub.add_parser("report", help="write the paper's results for a tuning job, or a study's figures")
    target = rp.add_mutually_exclusive_group(required=True)
    target.add_argument("--name", help="a tuning job's name")
    target.add_argument("--study", help="a study's name: its band plot (seeds) or heatmap (robustness)")
    rp.add_argument("--db", help=DB_HELP)
    rp.add_argument("--out", required=True, help="output directory")
    rp.add_argument("--baselines", type=_int_in(1, 100000), metavar="N",
                    help="random samples for the random-search baseline (default: as many as the job's evaluations)")
    rp.add_argument("--dask", metavar="ADDRESS", help=DASK_HELP)
    rp.add_argument("--rescore-samples", type=_int_in(1, 1000), default=20, metavar="N",
                    help="fresh seeds each theta of the table is rescored on (1..1000, default 20)")
    rp.set_defaults(func=_cmd_report)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except Exception as exc:
        message = _user_error(exc, args)
        if message is None:
            raise
        sys.stderr.write(f"driftlab: error: {message}\n")
        return 2


def _user_error(exc: Exception, args: argparse.Namespace) -> str | None:
    """The one line for an error the user can act on (bad input, no such job, a job held elsewhere, a file or
    database that cannot be used); None for a bug. The database and lifecycle modules are only consulted when
    already imported, so that `driftlab episode` does not load SQLAlchemy to start."""
    if isinstance(exc, (ConfigError, LookupError, OSError, ImportError)):
        return str(exc)
    lifecycle = sys.modules.get("driftlab.db.lifecycle")
    if lifecycle is not None and isinstance(exc, lifecycle.TransitionError):
        return str(exc)
    schema = sys.modules.get("driftlab.db.schema")
    if schema is not None and isinstance(exc, schema.NewerDatabaseError):
        return f"database {getattr(args, 'db', None) or '(default)'}: {exc}"
    sqlalchemy_exc = sys.modules.get("sqlalchemy.exc")
    if sqlalchemy_exc is not None and isinstance(exc, sqlalchemy_exc.SQLAlchemyError):
        reason = str(getattr(exc, "orig", None) or exc).splitlines()[0]
        return f"database {getattr(args, 'db', None) or '(default)'}: {reason}"
    return None


if __name__ == "__main__":
    sys.exit(main())
