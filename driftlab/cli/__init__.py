"""The `driftlab` command line: an edge over core/ (parsing, JSON output, files).

The subcommands, one module each: ``episode`` (equilibrium, episode), ``tune`` (tune, rescore, report), ``serve``,
``study``; ``options`` holds what they share.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from driftlab.cli.options import (
    DASK_HELP,
    DB_HELP,
    PLANT_CHOICES,
    PLANT_HELP,
    PLANT_METAVAR,
    Parser,
    add_job_options,
    dask_address,
    db_url,
    episode_controller,
    int_in,
    name_text,
    stored_db_url,
)
from driftlab.core.errors import ConfigError


def _command(module: str, name: str):
    """The subcommand ``name`` of driftlab.cli.<module>, imported when it runs: the parser refuses a bad argument
    without it."""
    def run(args: argparse.Namespace) -> int:
        return getattr(importlib.import_module(f"driftlab.cli.{module}"), name)(args)
    return run


cmd_equilibrium = _command("episode", "cmd_equilibrium")
cmd_episode = _command("episode", "cmd_episode")
cmd_tune = _command("tune", "cmd_tune")
cmd_rescore = _command("tune", "cmd_rescore")
cmd_report = _command("tune", "cmd_report")
cmd_serve = _command("serve", "cmd_serve")
cmd_calibrate = _command("calibrate", "cmd_calibrate")


def cmd_study(args: argparse.Namespace) -> int:
    from driftlab.cli.study import cmd_study
    from driftlab.cli.tune import tuning_spec

    dask = dask_address(args) if hasattr(args, "dask") else None
    url = stored_db_url(args.db) if args.kind == "show" else db_url(args.db)
    return cmd_study(args, tuning_spec, url, dask)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="driftlab", description="Learning-based inertia drift (Zhou et al. 2025).")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    eq = sub.add_parser("equilibrium", help="drift equilibrium of the model (and a plant) at radius and beta")
    eq.add_argument("--radius", type=float, action="append", metavar="R",
                    help="path radius R [m] (default 44; with --window, repeat it for several circles)")
    eq.add_argument("--beta", type=float, default=-0.4, help="sideslip [rad]; < 0 left-hand drift")
    eq.add_argument("--plant", choices=PLANT_CHOICES, metavar=PLANT_METAVAR,
                    help="also solve this plant's own equilibrium (for a CommonRoad plant its drift family: every "
                         "steady drift, and whether the main one countersteers)")
    eq.add_argument("--set", action="append", metavar="KEY=VALUE", help="config override, e.g. plant.cg_height_m=0.3")
    eq.add_argument("--window", action="store_true", help="instead: the drift window, the sideslips at which the "
                    "plant (default: DriftLab's) and the controller's model both drift both circles of an 8 of each "
                    "--radius (default: the scenario's and the circles a calibration tiles, 30/44 and 52/44 its "
                    "size), as the drivability check decides; one line a radius, and why where there is none")
    eq.set_defaults(func=cmd_equilibrium)
    ep = sub.add_parser("episode", help="run one 30 s figure-8 episode and print its metrics as JSON")
    ep.add_argument("--theta", help="c_lr=..,c_rl=..,dV=..,k=..,model_mu_scale=..,model_c_scale=.. (any subset; "
                    "defaults: 0.02, 0.02, 0, 0.05, 1, 1)")
    ep.add_argument("--plant", choices=PLANT_CHOICES, metavar=PLANT_METAVAR, default="default",
                    help=PLANT_HELP)
    ep.add_argument("--controller", type=episode_controller, default="default", metavar="CONTROLLER",
                    help="default: DriftLab's MPC with path states and actuator lags; paper: the paper's MPC; "
                         "policy:FILE: a learned policy (.npz, driftlab.gym.policy; the gym extra)")
    ep.add_argument("--set", action="append", metavar="KEY=VALUE", help="config override, e.g. mpc.q_sideslip=400")
    ep.add_argument("--seed", type=int, default=0, help="episode seed: the plant's per-episode variation, start and "
                    "sensor noise (default 0; the nominal plant has none)")
    ep.add_argument("--csv", help="write the trajectory to this CSV file (pandas.read_csv reads it as it is), and its "
                    "metadata (theta, seed, J, the config as run) beside it: FILE.csv -> FILE.json")
    ep.add_argument("--plot", help="write the paper's figures to this PNG file")
    ep.add_argument("--html", help="write a standalone 3D replay of the episode to this HTML file (no server needed)")
    ep.add_argument("--ghost", type=episode_controller, metavar="CONTROLLER",
                    help="with --html: also drive this controller (default, paper or policy:FILE) on the same seed, "
                         "as a translucent car beside the first")
    ep.add_argument("--ghost-theta", help="the ghost's theta, as --theta (default: --theta)")
    ep.set_defaults(func=cmd_episode)
    tu = sub.add_parser("tune", help="run (or resume) a Bayesian-optimization tuning job headless")
    add_job_options(tu)
    tu.add_argument("--seed", type=int, default=0, help="optimizer seed; also picks the episode seeds")
    tu.add_argument("--db", help=DB_HELP)
    tu.add_argument("--name", type=name_text, help="job name; an existing name resumes that job")
    tu.add_argument("--dask", metavar="ADDRESS", help=DASK_HELP)
    tu.add_argument("--workers", type=int_in(1, 1024), metavar="N",
                    help="episodes in flight at once, 1..1024 (default: 1 locally, the cluster's threads with --dask)")
    tu.set_defaults(func=cmd_tune)
    sv = sub.add_parser("serve", help="the dashboard and REST API (http://127.0.0.1:8000)")
    sv.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1: this machine only)")
    sv.add_argument("--port", type=int_in(1, 65535), default=8000, metavar="PORT",
                    help="TCP port, 1..65535 (default 8000)")
    sv.add_argument("--db", help=DB_HELP)
    sv.add_argument("--dask", metavar="ADDRESS", help=DASK_HELP)
    sv.add_argument("--workers", type=int_in(1, 1024), metavar="N",
                    help="episodes in flight at once, 1..1024 (default: 2 local processes, the cluster's threads "
                         "with --dask)")
    sv.set_defaults(func=cmd_serve)
    rs = sub.add_parser("rescore", help="run a job's best theta, exactly as stored, under fresh seeds; print JSON")
    rs.add_argument("--name", required=True)
    rs.add_argument("--db", help=DB_HELP)
    rs.add_argument("--samples", type=int_in(1, 1000), default=30, metavar="N",
                    help="episodes, each with a seed never used in tuning (1..1000, default 30)")
    rs.add_argument("--workers", type=int_in(1, 1024), metavar="N",
                    help="episodes in flight, 1..1024 (default: 2 local processes, the cluster's threads with --dask)")
    rs.add_argument("--dask", metavar="ADDRESS", help=DASK_HELP)
    rs.set_defaults(func=cmd_rescore)
    from driftlab.cli.calibrate import add_calibrate_parser
    from driftlab.cli.study import add_study_parser

    add_calibrate_parser(sub, DB_HELP, DASK_HELP, int_in, PLANT_CHOICES).set_defaults(func=cmd_calibrate)

    st = add_study_parser(sub, DB_HELP, DASK_HELP, int_in, add_job_options)
    st.set_defaults(func=cmd_study, seed=0)
    rp = sub.add_parser("report", help="write the paper's results for a tuning job, or a study's figures")
    target = rp.add_mutually_exclusive_group(required=True)
    target.add_argument("--name", help="a tuning job's name")
    target.add_argument("--study", help="a study's name: its band plot (seeds) or heatmap (robustness)")
    rp.add_argument("--db", help=DB_HELP)
    rp.add_argument("--out", required=True, help="output directory")
    rp.add_argument("--baselines", type=int_in(1, 100000), metavar="N",
                    help="random samples for the random-search baseline (default: as many as the job's evaluations)")
    rp.add_argument("--dask", metavar="ADDRESS", help=DASK_HELP)
    rp.add_argument("--rescore-samples", type=int_in(1, 1000), default=20, metavar="N",
                    help="fresh seeds each theta of the table is rescored on (1..1000, default 20)")
    rp.set_defaults(func=cmd_report)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return args.func(args)
    except Exception as exc:
        message = user_error(exc, args)
        if message is None:
            raise
        sys.stderr.write(f"driftlab: error: {message}\n")
        return 2


def user_error(exc: Exception, args: argparse.Namespace) -> str | None:
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
