"""One episode of the paper's scenario: plant, planner, controller, failure detection, metrics and J.

:func:`run_episode` never raises for a bad run: a diverging or failing simulation ends early with a status,
and its J is a penalty worse than any completed run's (see :func:`failure_penalty`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from driftlab.core.config import EpisodeConfig, Theta
from driftlab.core.controller import DriftController, build_controller_model
from driftlab.core.errors import ConfigError, NoEquilibriumError
from driftlab.core.metrics import EpisodeMetrics, compute_metrics
from driftlab.core.planner import InertiaDriftPlanner, Phase, Triggers
from driftlab.core.plant import (
    DRIVE,
    HEADING,
    N_PLANT_STATES,
    SIDESLIP,
    SPEED,
    STEER,
    X_POS,
    Y_POS,
    YAW_RATE,
    Plant,
)
from driftlab.core.track import FigureEight, track_errors, wrap_angle
from driftlab.core.variation import (
    MAX_SEED,
    NOISE_HEADING,
    NOISE_SIDESLIP,
    NOISE_SPEED,
    NOISE_X,
    NOISE_Y,
    NOISE_YAW_RATE,
    draw_variation,
)

STATUSES = ("completed", "spun_out", "left_track", "stalled", "gripped_up", "solver_failed", "diverged")

# Trajectory columns recorded at the controller rate, with units.
COLUMNS = (
    "t_s", "x_m", "y_m", "psi_rad", "V_mps", "beta_rad", "r_radps", "delta_cmd_rad", "delta_rad", "delta_mpc_rad",
    "Fxr_cmd_n", "Fxr_n", "e_m", "dpsi_rad", "c", "phase", "V_ref_mps", "beta_ref_rad", "r_ref_radps",
    "delta_ref_rad", "Fxr_ref_n", "osqp",
)
COL = {name: i for i, name in enumerate(COLUMNS)}


@dataclass
class EpisodeResult:
    """Status, J, metrics and the trajectory (rows at the controller rate, columns ``COLUMNS``)."""

    status: str
    J: float
    metrics: EpisodeMetrics
    trajectory: np.ndarray
    trigger_points: list[dict[str, float]] = field(default_factory=list)
    wall_ms: float = 0.0
    theta: Theta = field(default_factory=Theta)
    seed: int = 0

    @property
    def completed(self) -> bool:
        return self.status == "completed"

    def column(self, name: str) -> np.ndarray:
        return self.trajectory[:, COL[name]]

    def summary(self) -> dict:
        """The JSON object `driftlab episode` prints."""
        return {"status": self.status, "J": self.J, "theta": self.theta.as_dict(), "seed": self.seed,
                **self.metrics.as_dict(), "wall_ms": round(self.wall_ms, 2)}


class _FailureMonitor:
    """Applies :class:`FailureLimits` each step; returns a failure status or None."""

    def __init__(self, config: EpisodeConfig) -> None:
        self.limits = config.failure
        self.last_trigger_s = 0.0
        self.gripup_since: float | None = None

    def check(self, t_s: float, s: np.ndarray, lateral_error_m: float, beta_ref_rad: float) -> str | None:
        lim = self.limits
        if not np.all(np.isfinite(s)) or not math.isfinite(lateral_error_m):
            return "diverged"
        if abs(s[SIDESLIP]) > lim.max_sideslip_rad or abs(s[YAW_RATE]) > lim.max_yaw_rate_radps:
            return "spun_out"
        if abs(lateral_error_m) > lim.max_lateral_error_m:
            return "left_track"
        if s[SPEED] < lim.min_speed_mps:
            return "stalled"
        drifting = s[SIDESLIP] * beta_ref_rad > 0.0 and abs(s[SIDESLIP]) >= lim.gripup_sideslip_rad
        if drifting or t_s - self.last_trigger_s < lim.gripup_grace_s:
            self.gripup_since = None
        elif self.gripup_since is None:
            self.gripup_since = t_s
        elif t_s - self.gripup_since > lim.gripup_time_s:
            return "gripped_up"
        return None


def initial_plant_state(config: EpisodeConfig, track: FigureEight, speed_mps: float, sideslip_rad: float,
                        yaw_rate_radps: float, steer_rad: float, drive_n: float) -> np.ndarray:
    """The car on the start point of the left circle, in the given drift, actuators at the given inputs."""
    x0, y0, course = track.start_pose()
    s = np.zeros(N_PLANT_STATES)
    s[X_POS], s[Y_POS], s[HEADING] = x0, y0, wrap_angle(course - sideslip_rad)
    s[SPEED], s[SIDESLIP], s[YAW_RATE], s[STEER], s[DRIVE] = speed_mps, sideslip_rad, yaw_rate_radps, steer_rad, drive_n
    return s


def failure_penalty(completed_fraction: float) -> float:
    """J of a failed episode: above any completed episode's J, and lower the further the car got.

    A completed episode has |e| <= 10 m, |beta - beta_eq| <= 1.6 rad, |dpsi| <= pi at every step (else it
    would have failed), so its J <= log(10 + 5 pi + 1.6) = 3.31. Failures score 3.5 + 5 (1 - fraction).
    """
    return 3.5 + 5.0 * (1.0 - min(max(completed_fraction, 0.0), 1.0))


def run_episode(theta: Theta, config: EpisodeConfig, *, seed: int = 0) -> EpisodeResult:
    """Run the paper's figure-8 scenario once (paper Algorithm 1, inner loop) and score it (paper eq. 12).

    A pure function of its arguments: ``seed`` draws the episode's plant variation, start and measurement
    noise (:mod:`driftlab.core.variation`; none in a plant whose spreads are zero), and no state survives
    from one call to the next. The same arguments give a bit-identical trajectory in any process.
    """
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise ConfigError(f"seed must be an integer in [0, {MAX_SEED}], got {seed!r}")
    started = time.perf_counter()
    scenario = config.scenario
    track = FigureEight(scenario.left_radius_m, scenario.right_radius_m)
    try:
        model = build_controller_model(config.vehicle, config.mpc, scenario.left_radius_m,
                                       scenario.right_radius_m, scenario.sideslip_rad, theta.k, scenario.lookahead_m)
    except NoEquilibriumError:
        empty = np.zeros((0, len(COLUMNS)))
        return EpisodeResult("diverged", failure_penalty(0.0), compute_metrics(empty, [], track, COL), empty,
                             wall_ms=(time.perf_counter() - started) * 1e3, theta=theta, seed=seed)
    dt = config.mpc.dt_s
    n_steps = int(round(scenario.max_time_s / dt))
    variation = draw_variation(config.plant, seed, n_steps + 1)
    noise = variation.noise
    plant = Plant(variation.plant, config.vehicle)
    controller = DriftController(model, config.mpc, theta.dV, theta.k, scenario.lookahead_m)
    planner = InertiaDriftPlanner(Triggers(theta.c_lr, theta.c_rl), scenario.settle_tolerance_rad)
    monitor = _FailureMonitor(config)
    start = model.left
    offset = variation.start_offset
    state = initial_plant_state(config, track, start.speed_mps + theta.dV + offset[0], start.sideslip_rad + offset[1],
                                start.yaw_rate_radps + offset[2], start.steer_rad, start.drive_force_n)
    rows = np.zeros((n_steps + 1, len(COLUMNS)))
    status = "completed"
    n_rows = 0
    for step in range(n_steps + 1):
        t = step * dt
        # What the sensors report (the planner and the controller see this; J and the failure rules the truth).
        sensed = _measured(state, noise[step]) if variation.noisy else state
        circle = track.circle(planner.phase.direction)
        seen = track_errors(circle, sensed[X_POS], sensed[Y_POS], sensed[HEADING] + sensed[SIDESLIP])
        ref = controller.reference(planner.phase.direction)
        phase = planner.update(t, sensed[X_POS], sensed[Y_POS], seen.trigger_fraction, sensed[SIDESLIP] - ref[1])
        if phase != Phase.FINISHED and phase.direction != circle.direction:
            circle = track.circle(phase.direction)
            seen = track_errors(circle, sensed[X_POS], sensed[Y_POS], sensed[HEADING] + sensed[SIDESLIP])
            ref = controller.reference(phase.direction)
            monitor.last_trigger_s = t
        errors = track_errors(circle, state[X_POS], state[Y_POS], state[HEADING] + state[SIDESLIP]) \
            if variation.noisy else seen
        row = rows[n_rows]
        row[COL["t_s"]] = t
        row[COL["x_m"]], row[COL["y_m"]], row[COL["psi_rad"]] = state[X_POS], state[Y_POS], state[HEADING]
        row[COL["V_mps"]], row[COL["beta_rad"]], row[COL["r_radps"]] = state[SPEED], state[SIDESLIP], state[YAW_RATE]
        row[COL["delta_rad"]], row[COL["Fxr_n"]] = state[STEER], state[DRIVE]
        row[COL["e_m"]], row[COL["dpsi_rad"]], row[COL["c"]] = errors.lateral_error_m, errors.course_error_rad, \
            errors.trigger_fraction
        row[COL["phase"]] = phase
        row[COL["V_ref_mps"]], row[COL["beta_ref_rad"]], row[COL["r_ref_radps"]] = ref[0], ref[1], ref[2]
        row[COL["delta_ref_rad"]], row[COL["Fxr_ref_n"]] = ref[3], ref[4] * 1e3
        n_rows += 1
        failure = monitor.check(t, state, errors.lateral_error_m, ref[1])
        if failure is not None:
            status = failure
            break
        if phase == Phase.FINISHED:
            break
        controller.freeze_estimate(not phase.is_sustained)
        measured = np.array([sensed[SPEED], sensed[SIDESLIP], sensed[YAW_RATE]])
        actuators = np.array([state[STEER], state[DRIVE]])
        steer, drive, solution = controller.step(measured, actuators, phase.direction, seen.lateral_error_m,
                                                 seen.course_error_rad)
        row[COL["delta_cmd_rad"]], row[COL["delta_mpc_rad"]], row[COL["Fxr_cmd_n"]] = steer, solution.steer_rad, drive
        row[COL["osqp"]] = 1.0 if solution.used_osqp else 0.0
        if not solution.ok:
            status = "solver_failed"
            break
        state = plant.step(state, steer, drive, dt)
    else:
        status = "stalled"  # out of time before finishing the 8
    trajectory = rows[:n_rows]
    triggers = [{"t_s": e.time_s, "x_m": e.x_m, "y_m": e.y_m, "phase": int(e.phase)}
                for e in planner.trigger_events]
    metrics = compute_metrics(trajectory, [e["t_s"] for e in triggers], track, COL)
    if status == "completed":
        j_value = metrics.objective_j
    else:
        j_value = failure_penalty(metrics.completed_fraction)
    return EpisodeResult(status, float(j_value), metrics, trajectory, triggers,
                         wall_ms=(time.perf_counter() - started) * 1e3, theta=theta, seed=seed)


def _measured(state: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """The plant state as the sensors report it: pose and [V, beta, r] with this step's noise."""
    sensed = state.copy()
    sensed[X_POS] += noise[NOISE_X]
    sensed[Y_POS] += noise[NOISE_Y]
    sensed[HEADING] += noise[NOISE_HEADING]
    sensed[SPEED] += noise[NOISE_SPEED]
    sensed[SIDESLIP] += noise[NOISE_SIDESLIP]
    sensed[YAW_RATE] += noise[NOISE_YAW_RATE]
    return sensed
