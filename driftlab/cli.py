"""The `driftlab` command line: an edge over core/ (parsing, JSON output, files)."""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
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
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ConfigError as exc:
        sys.stderr.write(f"driftlab: error: {exc}\n")
        return 2


if __name__ == "__main__":
    sys.exit(main())
