"""`driftlab equilibrium` and `driftlab episode`: one drift equilibrium, one episode (JSON, CSV, plot)."""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

from driftlab.cli.options import (
    PLOT_SUFFIXES,
    POLICY_PREFIX,
    check_output_file,
    episode_config,
    finite,
    key_values,
)
from driftlab.core.config import Theta, config_to_dict
from driftlab.core.configure import fitted
from driftlab.core.drivability import check_drivable, drift_window
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.errors import ConfigError, NoEquilibriumError
from driftlab.core.plants import entry_of
from driftlab.core.track import tiled_radii
from driftlab.core.vehicle import pack_params
from driftlab.reports.export import metadata_path

DEFAULT_RADIUS_M = 44.0


def cmd_equilibrium(args: argparse.Namespace) -> int:
    if args.window:
        return _print_window(args)
    if args.radius and len(args.radius) > 1:
        raise ConfigError("--radius: one radius for an equilibrium (several only with --window)")
    radius_m = args.radius[0] if args.radius else DEFAULT_RADIUS_M
    config = fitted(episode_config(args))
    try:
        eq = drift_equilibrium(radius_m, args.beta, pack_params(config.vehicle))
    except NoEquilibriumError as exc:
        sys.stderr.write(f"driftlab: error: {exc}\n")
        return 2
    out: dict[str, Any] = eq.as_dict()
    if args.plant:
        plant = entry_of(config.plant).equilibrium_summary(config.plant, config.vehicle, radius_m, args.beta)
        if plant is not None and "V" in plant:
            # The drive the car applies: a CommonRoad car's through its wheel (drive_n), DriftLab's its Fxr.
            plant["mismatch"] = {"dV": plant["V"] - eq.speed_mps, "ddelta": plant["delta"] - eq.steer_rad,
                                 "dFxr": plant.get("drive_n", plant["Fxr"]) - eq.drive_force_n}
        out["plant"] = plant if plant is not None else {"error": f"plant.model {config.plant.model!r}: its own "
                                                                  "drift is not known to DriftLab"}
    print(json.dumps(out))
    return 0


def _print_window(args: argparse.Namespace) -> int:
    """The drift window on each --radius (default: the scenario's circles and those a calibration tiles), one JSON
    line a radius; a radius without a drift is a line with the reason, not an error. It does not depend on the
    scenario's sideslip: a car whose model is fitted at each drift is checked as a job there would be
    (driftlab.core.drivability.drift_window)."""
    config = episode_config(args)
    scenario = config.scenario
    if args.radius:
        radii = sorted(set(args.radius))
    else:
        radii = sorted({*tiled_radii(scenario.left_radius_m), *tiled_radii(scenario.right_radius_m)})
    lines = [json.dumps(drift_window(config, radius).as_dict()) for radius in radii]
    print('{"window": [\n' + ",\n".join(lines) + "\n]}")
    return 0


def _run(args: argparse.Namespace, controller: str, theta: Theta, config: Any) -> Any:
    """The episode of ``controller`` (default, paper or policy:FILE) on ``--plant``, ``--set`` and ``--seed``. A
    learned policy (driftlab.gym.policy) drives the environment's episode of the same plant, keys and seed."""
    from driftlab.core.episode import run_episode

    if not controller.startswith(POLICY_PREFIX):
        if controller != args.controller:  # the ghost's MPC: its own preset, the same keys
            args = argparse.Namespace(**{**vars(args), "controller": controller})
            config = fitted(episode_config(args))
        return run_episode(theta, config, seed=args.seed)
    try:
        from driftlab.gym import FigureEightEnv
        from driftlab.gym.policy import MlpPolicy, PolicyController, run_policy_episode
    except ImportError as exc:
        raise ConfigError(f"--controller policy:FILE needs the gym extra (pip install 'driftlab[gym]'): {exc}",
                          field="controller") from exc
    policy = MlpPolicy.load(controller[len(POLICY_PREFIX):])
    env = FigureEightEnv(plant=args.plant, controller="default", config=key_values(args.set or [], "--set"),
                         theta=theta.as_dict())
    return run_policy_episode(env, PolicyController(policy, env), args.seed)


def _theta(text: str | None, option: str) -> Theta:
    return Theta.from_mapping(key_values(text.split(",") if text else [], option))


def _write_html(args: argparse.Namespace, result: Any, config: Any, theta: Theta) -> None:
    """The standalone replay (driftlab.web.recording), with the ghost's episode beside it."""
    from driftlab.core.episode import COLUMNS
    from driftlab.core.track import FigureEight
    from driftlab.web.frames import frames_of_result
    from driftlab.web.recording import EpisodeRecorder

    scenario = config.scenario
    track = FigureEight(scenario.left_radius_m, scenario.right_radius_m, scenario.laps)
    ghost = None
    if args.ghost:
        ghost_theta = _theta(args.ghost_theta, "--ghost-theta") if args.ghost_theta else theta
        ghost = frames_of_result(COLUMNS, _run(args, args.ghost, ghost_theta, config), f"{args.ghost} controller")
    recorder = EpisodeRecorder()
    try:
        page = recorder.html(frames_of_result(COLUMNS, result, f"{args.controller} controller"), track, ghost)
    finally:
        recorder.stop()
    with open(args.html, "w") as handle:
        handle.write(page)


def cmd_episode(args: argparse.Namespace) -> int:
    from driftlab.core.episode import COLUMNS
    from driftlab.core.track import FigureEight

    config = episode_config(args)
    theta = _theta(args.theta, "--theta")
    if (args.ghost or args.ghost_theta) and not args.html:
        raise ConfigError("--ghost and --ghost-theta go with --html (the replay they are drawn in)", field="ghost")
    sidecar = metadata_path(args.csv) if args.csv else None
    outputs = (("--csv", args.csv), ("--csv", sidecar), ("--plot", args.plot), ("--html", args.html))
    for option, path in outputs:  # before the episode runs
        check_output_file(option, path)
    if args.plot and os.path.splitext(args.plot)[1].lower() not in PLOT_SUFFIXES:
        raise ConfigError(f"--plot {args.plot}: the file name must end in one of {', '.join(PLOT_SUFFIXES)}")
    check_drivable(config)
    config = fitted(config)  # what runs, and what the CSV records for a re-run
    result = _run(args, args.controller, theta, config)
    summary = finite(result.summary())
    if args.controller.startswith(POLICY_PREFIX):
        summary["controller"] = args.controller
    print(json.dumps(summary))
    if args.csv:
        from driftlab.reports.export import metadata_json, trajectory_csv, with_lap_column

        metadata = {"theta": theta.as_dict(), "seed": args.seed, "controller": args.controller,
                    "J_episode": result.J, "episode_status": result.status,
                    "J": result.J, "status": result.status, "n_seeds": 1, "config": config_to_dict(config)}
        with open(args.csv, "w", newline="") as handle:
            track = FigureEight(config.scenario.left_radius_m, config.scenario.right_radius_m, config.scenario.laps)
            handle.write(trajectory_csv(*with_lap_column(list(COLUMNS), result.trajectory, track)))
        with open(str(sidecar), "w") as handle:
            handle.write(metadata_json(metadata))
    if args.html:
        _write_html(args, result, config, theta)
    if args.plot:
        from driftlab.reports.plotting import plot_episode

        scenario = config.scenario
        plot_episode(result, FigureEight(scenario.left_radius_m, scenario.right_radius_m, scenario.laps), args.plot,
                     title=f"{args.plant} plant, {args.controller} controller, seed {args.seed}\n"
                           f"theta {', '.join(f'{k} {v:.4g}' for k, v in theta.as_dict().items())}\n"
                           f"{result.status}, J = {result.J:.3f}", lap_errors_m=result.metrics.lap_mean_abs_e_m)
    return 0
