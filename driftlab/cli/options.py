"""What the subcommands share: argument types, the config from --plant and --set, the database and the cluster."""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from driftlab.core.errors import ConfigError
from driftlab.core.limits import DEFAULT_CONFIRM_SAMPLES, DEFAULT_ROBUST_SAMPLES, JOB_LIMITS, MAX_ROBUST_SAMPLES
from driftlab.names import name_problem

# The parser is built from light modules only, so that a bad argument is refused before the simulation, its solvers
# and SQLAlchemy are imported (a second); each command imports what it runs.
if TYPE_CHECKING:
    from driftlab.core.config import EpisodeConfig
    from driftlab.settings import Settings

DB_HELP = ("SQLite file or SQLAlchemy URL (default: DRIFTLAB_DATABASE_URL, else the shared "
           "~/.local/share/driftlab/driftlab.db)")


def int_in(lo: int, hi: int):
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


class Parser(argparse.ArgumentParser):
    """argparse that reports bad arguments on one line with exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(f"driftlab: error: {message}\n")
        sys.exit(2)


def name_text(text: str) -> str:
    """A job's or a study's name, as the REST API takes it (driftlab.names)."""
    problem = name_problem(text)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return text


def finite(value: Any) -> Any:
    """JSON has no NaN: non-finite numbers become null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, list):
        return [finite(v) for v in value]
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    return value


PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def check_output_file(option: str, path: str | None) -> None:
    """A file we may write: not a folder, in a folder that exists."""
    if not path:
        return
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise ConfigError(f"{option} {path}: is a folder; give a file name")
    if not os.path.isdir(folder):
        raise ConfigError(f"{option} {path}: the folder {folder} does not exist")


def key_values(items: list[str], what: str) -> dict[str, str]:
    pairs = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"{what} expects key=value, got {item!r}")
        if key.strip() in pairs:
            raise ConfigError(f"{what} sets {key.strip()!r} twice")
        pairs[key.strip()] = value.strip()
    return pairs


class PlantChoices:
    """``--plant``'s choices: the presets and any plant installed beside DriftLab, read from the plant catalog only
    when argparse asks (a --plant given, or a help text), not when the parser is built."""

    def _names(self) -> tuple[str, ...]:
        from driftlab.core.configure import PLANT_PRESETS
        from driftlab.core.plants import installed_names

        return (*PLANT_PRESETS, *installed_names())

    def __contains__(self, name: object) -> bool:
        return name in self._names()

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())


PLANT_CHOICES = PlantChoices()
PLANT_METAVAR = "PLANT"  # argparse lists a metavar's choices only in an error: the catalog is read then
PLANT_HELP = ("a plant preset: default, nominal, commonroad_std, commonroad_mb, or a plant installed beside DriftLab "
              "(default: default)")


POLICY_PREFIX = "policy:"


def episode_controller(text: str) -> str:
    """`driftlab episode --controller`: default, paper, or policy:FILE (a learned policy, driftlab.gym.policy)."""
    if text in ("default", "paper") or (text.startswith(POLICY_PREFIX) and len(text) > len(POLICY_PREFIX)):
        return text
    raise argparse.ArgumentTypeError(f"must be default, paper or policy:FILE (a policy .npz), got {text!r}")


def mpc_preset(args: argparse.Namespace) -> str:
    """The MPC preset of ``--controller``: a learned policy's commands are bounded as the default MPC's."""
    controller = getattr(args, "controller", "default")
    return "default" if controller.startswith(POLICY_PREFIX) else controller


def episode_config(args: argparse.Namespace, *, inside_window: bool = False) -> EpisodeConfig:
    """The config of ``--plant``, ``--controller`` and ``--set``; ``inside_window``: at the middle of the car's drift
    window where the preset's sideslip is outside it (driftlab.core.configure.overrides_inside_window)."""
    from driftlab.core.configure import apply_overrides, overrides_inside_window, preset_config

    preset = preset_config(args.plant or "default", mpc_preset(args))
    parse = overrides_inside_window if inside_window else apply_overrides
    return parse(preset, key_values(args.set or [], "--set"))


def machine_cores() -> int:
    """The cores this process may run on: its CPU affinity where the OS reports one (a container's limit), else
    the machine's."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # macOS and Windows have no affinity call
        return os.cpu_count() or 1


def dask_address(args: argparse.Namespace) -> str | None:
    return args.dask or settings().dask_address


def settings() -> Settings:
    """The DRIFTLAB_* settings of this command (driftlab.settings.Settings), read once."""
    global _SETTINGS
    if _SETTINGS is None:
        from driftlab.settings import Settings

        _SETTINGS = Settings()
    return _SETTINGS


_SETTINGS: Settings | None = None


def db_url(db: str | None) -> str:
    from driftlab.settings import database_url

    return database_url(db, settings())


def stored_db_url(db: str | None) -> str:
    """The database of a command that only reads what is stored (rescore, report, study show): a --db file that
    does not exist is refused instead of created empty (a typo would otherwise say "no job named ...")."""
    url = db_url(db)
    if url.startswith("sqlite:///") and not os.path.exists(url[len("sqlite:///"):]):
        raise ConfigError(f"--db {db or url}: no such database file ({url[len('sqlite:///'):]}); "
                          "`driftlab tune` or `driftlab serve` creates one")
    return url


def add_job_options(parser: argparse.ArgumentParser) -> None:
    """The options of a tuning job's specification (shared by `tune` and `study seeds`), but its seed."""
    parser.add_argument("--iterations", type=int_in(*JOB_LIMITS["iterations"]), metavar="N",
                        help="evaluations in total (default 500 for a new job); on a "
                        "stored job a new budget: a finished job continues to it")
    parser.add_argument("--preset", choices=("default", "paper"), default="default",
                        help="paper: the paper's BO, 500 iterations, 20 space-filling points, active set 400, "
                             "theta's four parameters only (default: 12 space-filling points, model correction on); "
                             "options given explicitly win")
    parser.add_argument("--model-correction", choices=("on", "off"),
                        help="also learn the controller model's friction and tyre-C scales (theta.model_mu_scale, "
                             "theta.model_c_scale); default on, off with --preset paper")
    parser.add_argument("--local-phase", choices=("on", "off"),
                        help="with model correction: start near the uncorrected model and widen the search as the "
                             "models learn (default: on for DriftLab's plants, off for others, e.g. CommonRoad's)")
    parser.add_argument("--deterministic", action="store_true", default=None,
                        help="one evaluation at a time (its seeds still in parallel): the thetas depend on the seed "
                             "and settings only, not on the number of workers or which episode finishes first")
    parser.add_argument("--prune", metavar="off|CONFIDENCE,MIN_SEEDS",
                        help="stop a theta whose first seeds are worse than the best's on the same seeds with "
                             "confidence (default: on, 0.95,2; off: every evaluation runs every seed)")
    parser.add_argument("--time-budget", type=float, metavar="SECONDS",
                        help="finish the job once it has run this long in all (its runs' wall time), budget or not")
    parser.add_argument("--stop-after-no-improvement", metavar="N[:BY]",
                        help="finish the job once its best J has not fallen by more than BY (default 0) in its "
                             "last N evaluations, e.g. 40:0.01")
    parser.add_argument("--enqueue", action="append", metavar="THETA",
                        help="a hand-picked theta to evaluate next, e.g. k=0.06,dV=0.1 (the keys not given "
                             "untuned; inside the job's box); repeat it for more, in order. To a job a server "
                             "runs (same --db): handed to that server, which evaluates it next")
    parser.add_argument("--warm-start-from", metavar="IDS",
                        help="start from these stored jobs' evaluations, e.g. 3,4 (job ids): told to the optimizer "
                             "where a job ran the same config, else its best thetas are asked first")
    parser.add_argument("--seed-points", type=int_in(*JOB_LIMITS["seed_points"]), metavar="N",
                        help="space-filling evaluations before the GP (default 12)")
    parser.add_argument("--active-set", type=int_in(*JOB_LIMITS["active_set"]), metavar="N",
                        help="most evaluations the GP is fit on (default 400)")
    parser.add_argument("--robust-samples", type=int_in(*JOB_LIMITS["robust_samples"]), default=DEFAULT_ROBUST_SAMPLES,
                        metavar="N",
                        help=f"seeded episodes per evaluation, 1..{MAX_ROBUST_SAMPLES} (default "
                             f"{DEFAULT_ROBUST_SAMPLES}): J is their mean and an evaluation completes only if all "
                             "of them do")
    parser.add_argument("--confirm-samples", type=int_in(*JOB_LIMITS["confirm_samples"]), metavar="N",
                        default=DEFAULT_CONFIRM_SAMPLES,
                        help=f"more seeds an evaluation must also complete before it counts as the best so far "
                             f"(0..64, default {DEFAULT_CONFIRM_SAMPLES}; 0: off)")
    parser.add_argument("--plant", choices=PLANT_CHOICES, metavar=PLANT_METAVAR, default="default",
                        help="the plant preset the --set overrides start from (commonroad_std: CommonRoad's STD, "
                             "vehicle 2, sideslip 0.5, needs the commonroad extra)")
    parser.add_argument("--controller", choices=("default", "paper"), default="default")
    parser.add_argument("--set", action="append", metavar="KEY=VALUE",
                        help="config override, e.g. plant.steer_lag_s=0.02")
    parser.add_argument("--bound", action="append", metavar="NAME=LO:HI", help="theta bound, e.g. k=0:0.1 or "
                        "model_c_scale=0.9:1.2")


def prune_rule(text: str | None):
    """``--prune off`` or ``--prune CONFIDENCE,MIN_SEEDS``: a job's or a calibration's prune rule (None: default)."""
    from driftlab.core.pruning import PruneRule

    if text is None:
        return PruneRule()
    if text == "off":
        return PruneRule(enabled=False)
    confidence, _, seeds = text.partition(",")
    try:
        level, count = float(confidence), int(seeds)
    except ValueError:
        raise ConfigError(f"--prune must be off or CONFIDENCE,MIN_SEEDS, e.g. 0.95,2; got {text!r}",
                          field="prune") from None
    return PruneRule(confidence=level, min_seeds=count)  # its ranges, naming the field
