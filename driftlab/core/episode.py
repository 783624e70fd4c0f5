"""One episode of the paper's scenario: plant, planner, controller, failure detection, metrics and J.

:func:`run_episode` never raises for a bad run: a diverging or failing simulation ends early with a status,
and its J is a penalty worse than any completed run's (see :func:`failure_penalty`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from driftlab.core.blas_threads import with_one_blas_thread
from driftlab.core.closed_loop import finish_step, run_until_constrained
from driftlab.core.config import EpisodeConfig, Theta
from driftlab.core.configure import fitted
from driftlab.core.controller import ControllerModel, build_controller_model, has_drift, no_drift_reason
from driftlab.core.errors import ConfigError, NoEquilibriumError
from driftlab.core.loop_state import (
    COL,
    COLUMNS,
    DONE,
    I_DIRECTION,
    I_EVENTS,
    I_PLANT_DUE,
    I_ROWS,
    I_STATUS,
    NEEDS_QP,
    STATUSES,
    LoopSettings,
    LoopState,
    new_loop_state,
)
from driftlab.core.metrics import EpisodeMetrics, compute_metrics
from driftlab.core.mpc import QpSession
from driftlab.core.mpc.daqp_kernel import quadprog_address
from driftlab.core.planner import Phase, initial_plan_state
from driftlab.core.plant import (
    DRIVE,
    HEADING,
    N_PLANT_STATES,
    PLANT_EXTERNAL,
    SIDESLIP,
    SPEED,
    STEER,
    X_POS,
    Y_POS,
    YAW_RATE,
)
from driftlab.core.plants import make_plant
from driftlab.core.statuses import EpisodeStatus
from driftlab.core.track import LEFT, RIGHT, FigureEight, wrap_angle
from driftlab.core.variation import MAX_SEED, draw_variation

__all__ = ["COL", "COLUMNS", "STATUSES", "EpisodeResult", "EpisodeRun", "drive_episode", "episode_result",
           "failure_penalty", "run_episode", "start_episode"]


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
        return self.status == EpisodeStatus.COMPLETED

    @property
    def column_index(self) -> dict[str, int]:
        return COL

    def column(self, name: str) -> np.ndarray:
        return self.trajectory[:, COL[name]]

    def summary(self) -> dict:
        """The JSON object `driftlab episode` prints."""
        return {"status": self.status, "J": self.J, "theta": self.theta.as_dict(), "seed": self.seed,
                **self.metrics.as_dict(), "wall_ms": round(self.wall_ms, 2)}


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


def _refusal_text(theta: Theta, reason: str) -> str:
    return (f"the controller's model (model_mu_scale {theta.model_mu_scale:g}, model_c_scale "
            f"{theta.model_c_scale:g}) has no drift to hold: {reason}")


def refusal_reason(theta: Theta, config: EpisodeConfig) -> str | None:
    """Why an episode of ``theta`` would stop before its first step, refused: its model corrections leave the
    controller's model without a drift on the scenario's circles (None: it runs). Solves the model's two drift
    equilibria only (~10 ms), none of the QPs."""
    config = fitted(config)
    s = config.scenario
    reason = no_drift_reason(theta.model_vehicle(config.vehicle), s.left_radius_m, s.right_radius_m, s.sideslip_rad)
    return None if reason is None else _refusal_text(theta, reason)


def runs(config: EpisodeConfig, theta: dict[str, float]) -> bool:
    """Whether an episode of ``theta`` (any subset of its keys; the others untuned) would run: the optimizer's
    known constraint (driftlab.core.optimizer.BayesianOptimizer's ``feasible``): :func:`refusal_reason` is None,
    without solving more of the model's drift than it takes to find it."""
    config = fitted(config)
    s = config.scenario
    vehicle = Theta.from_mapping(Theta.filled(theta)).model_vehicle(config.vehicle)
    return has_drift(vehicle, s.left_radius_m, s.right_radius_m, s.sideslip_rad)


@dataclass
class EpisodeRun:
    """One episode under way: its constants, the compiled loop's state and the plant it steps. What
    :func:`run_episode` drives with its controller, and what the Gymnasium environment (driftlab.gym) steps with a
    policy's commands: both start it with :func:`start_episode` and score it with :func:`episode_result`.

    Attributes:
        settings: the loop's constants (:class:`~driftlab.core.closed_loop.LoopSettings`).
        loop: the loop's state, updated in place by the compiled halves of a step.
        plant: the plant's stepper (driftlab.core.plants); ``plant_args`` its compiled parameters (placeholders of
            the same types for a plant stepped in Python, ``plant.kind`` PLANT_EXTERNAL).
        noise: the episode's measurement noise, one row a control step.
    """

    theta: Theta
    config: EpisodeConfig
    seed: int
    track: FigureEight
    model: ControllerModel
    plant: Any
    plant_args: tuple[np.ndarray, np.ndarray]
    settings: LoopSettings
    loop: LoopState
    noise: np.ndarray
    started_s: float

    @property
    def status_code(self) -> int:
        """The kernel's status (RUNNING while under way, else an index of STATUSES)."""
        return int(self.loop.ints[I_STATUS])

    def step_python_plant(self) -> bool:
        """Step a plant stepped in Python (PLANT_EXTERNAL) under the commands sent, if the loop asks; True once the
        plant ends the episode as invalid (its status set)."""
        loop = self.loop
        if not loop.ints[I_PLANT_DUE]:
            return False
        loop.plant[:] = self.plant.step(loop.plant, float(loop.last_applied[0]), float(loop.last_applied[1]),
                                        self.settings.dt_s)
        loop.ints[I_PLANT_DUE] = 0
        return bool(hasattr(self.plant, "ended_invalid") and self.plant.ended_invalid(loop))


def _seed_checked(seed: int) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise ConfigError(f"seed must be an integer in [0, {MAX_SEED}], got {seed!r}")
    return seed


def start_episode(theta: Theta, config: EpisodeConfig, seed: int = 0,
                  started_s: float | None = None) -> EpisodeRun:
    """The episode of (theta, config, seed) at its start: the plant drawn from the seed (driftlab.core.variation) in
    the scenario's first drift, the loop before its first step.

    Raises:
        ConfigError: a seed outside [0, 2^63 - 1].
        NoEquilibriumError: theta's model corrections leave the controller's model without a drift to hold.
    """
    started = time.perf_counter() if started_s is None else started_s
    config = fitted(config)  # a config parsed, not yet run (driftlab.core.configure.fitted); the fit is cached
    scenario = config.scenario
    track = FigureEight(scenario.left_radius_m, scenario.right_radius_m, scenario.laps)
    model = build_controller_model(theta.model_vehicle(config.vehicle), config.mpc, scenario.left_radius_m,
                                   scenario.right_radius_m, scenario.sideslip_rad, theta.k, scenario.lookahead_m)
    dt = config.mpc.dt_s
    n_steps = int(round(scenario.max_time_s * scenario.laps / dt))
    variation = draw_variation(config.plant, _seed_checked(seed), n_steps + 1)
    plant = make_plant(variation.plant, config.vehicle)
    if hasattr(plant, "start_in_drift_of"):  # a multi-body car starts with its body rolled as in the drift
        plant.start_in_drift_of(scenario.left_radius_m, scenario.sideslip_rad)
    if hasattr(plant, "end_invalid_after") and config.failure.invalid_ends_episode:
        plant.end_invalid_after(config.failure.max_invalid_s)
    start = model.left
    offset = variation.start_offset
    state = plant.start_state(initial_plant_state(
        config, track, start.speed_mps + theta.dV + offset[0], start.sideslip_rad + offset[1],
        start.yaw_rate_radps + offset[2], start.steer_rad, start.drive_force_n))
    settings = _loop_settings(config, theta, track, n_steps, variation.noisy, plant.kind, model)
    loop = new_loop_state(state, initial_plan_state(scenario.laps), start.inputs, n_steps,
                          len(model.left_qp.step_limit))
    # A plant stepped in Python has no compiled parameters: the kernel gets placeholders of the same types.
    args = (plant.params, plant.actuators) if plant.kind != PLANT_EXTERNAL else (np.zeros(1), np.zeros(4))
    return EpisodeRun(theta, config, seed, track, model, plant, args, settings, loop, variation.noise, started)


def episode_result(run: EpisodeRun) -> EpisodeResult:
    """The status, metrics and J of an episode that has ended (paper eq. 12; a failure's J by
    :func:`failure_penalty`)."""
    loop = run.loop
    status = STATUSES[int(loop.ints[I_STATUS])]
    trajectory = loop.rows[:int(loop.ints[I_ROWS])].copy()
    triggers = [{"t_s": float(t), "x_m": float(x), "y_m": float(y), "phase": int(phase)}
                for t, phase, x, y in loop.events[:int(loop.ints[I_EVENTS])]
                if phase in (Phase.INERTIA_LEFT_TO_RIGHT, Phase.INERTIA_RIGHT_TO_LEFT)]
    metrics = compute_metrics(trajectory, [e["t_s"] for e in triggers], run.track, COL,
                              run.config.scenario.settle_tolerance_rad)
    if hasattr(run.plant, "validity"):
        metrics = replace(metrics, plant_validity=run.plant.validity())
    if status == EpisodeStatus.COMPLETED:
        j_value = metrics.objective_j
    else:
        j_value = failure_penalty(metrics.completed_fraction)
    return EpisodeResult(status, float(j_value), metrics, trajectory, triggers,
                         wall_ms=(time.perf_counter() - run.started_s) * 1e3, theta=run.theta, seed=run.seed)


def refused_result(theta: Theta, config: EpisodeConfig, seed: int, reason: str, started_s: float) -> EpisodeResult:
    """The result of an episode that never ran: the controller's model has no drift to hold (``reason``)."""
    scenario = config.scenario
    track = FigureEight(scenario.left_radius_m, scenario.right_radius_m, scenario.laps)
    empty = np.zeros((0, len(COLUMNS)))
    metrics = replace(compute_metrics(empty, [], track, COL), failure_reason=_refusal_text(theta, reason))
    return EpisodeResult(EpisodeStatus.REFUSED, failure_penalty(0.0), metrics, empty,
                         wall_ms=(time.perf_counter() - started_s) * 1e3, theta=theta, seed=seed)


@with_one_blas_thread
def run_episode(theta: Theta, config: EpisodeConfig, *, seed: int = 0) -> EpisodeResult:
    """Run the paper's figure-8 scenario once (paper Algorithm 1, inner loop) and score it (paper eq. 12).

    A pure function of its arguments: ``seed`` draws the episode's plant variation, start and measurement
    noise (:mod:`driftlab.core.variation`; none in a plant whose spreads are zero), and no state survives
    from one call to the next. The same arguments give a bit-identical trajectory in any process on one
    machine and lock, whatever its BLAS thread settings (:mod:`driftlab.core.blas_threads`).
    """
    _seed_checked(seed)
    started = time.perf_counter()
    try:
        run = start_episode(theta, config, seed, started)
    except NoEquilibriumError as exc:
        return refused_result(theta, config, seed, str(exc), started)
    drive_episode(run)
    return episode_result(run)


def drive_episode(run: EpisodeRun) -> None:
    """Drive an episode to its end with its own controller (the MPC and the paper's steering feedback)."""
    model, settings, loop, noise = run.model, run.settings, run.loop, run.noise
    # OSQP runs here, between stretches of the compiled loop (DAQP runs inside it); its warm start lives and dies
    # with the episode. A fresh solver per episode: no OSQP warm start or cache survives into the next one.
    sessions = {LEFT: QpSession(model.left_qp), RIGHT: QpSession(model.right_qp)}
    qa_left, qa_right = model.left_qp.arrays, model.right_qp.arrays
    args = run.plant_args

    # One loop for every plant: the kernel returns here for a constrained QP, and, for a plant without a compiled
    # step (plant.kind PLANT_EXTERNAL), after each control step for the plant's own Python step, unless the plant
    # brings a compiled loop of its own that steps it (``run_loop``, CommonRoad's MB).
    def run_kernel(settings, loop, qa_left, qa_right, model_params, noise):
        return run_until_constrained(settings, loop, qa_left, qa_right, model_params, *args, noise)

    run_loop = getattr(run.plant, "run_loop", None) or run_kernel
    while (code := run_loop(settings, loop, qa_left, qa_right, model.params, noise)) != DONE:
        if code == NEEDS_QP:
            direction = int(loop.ints[I_DIRECTION])
            du, ok = sessions[direction].solve_constrained(loop.qp_q, loop.qp_lower, loop.qp_upper)
            finish_step(settings, loop, qa_left if direction == LEFT else qa_right, *args, du, ok, True)
            if loop.ints[I_STATUS] >= 0:
                break
        if run.step_python_plant():
            break


def _loop_settings(config: EpisodeConfig, theta: Theta, track: FigureEight, n_steps: int,
                   noisy: bool, plant_kind: int, model: ControllerModel) -> LoopSettings:
    mpc, scenario, failure = config.mpc, config.scenario, config.failure
    left, right = track.left, track.right
    # Where the circles differ: dV scaled by each circle's drift speed (a relative correction, as a mismatch in
    # grip moves both drift speeds by about the same share), and the planned speed change before each flick.
    # Equal radii keep dV as it is and no speed change (the stored episodes' bits).
    differ = left.radius_m != right.radius_m
    right_scale = model.right.speed_mps / model.left.speed_mps if differ else 1.0
    return LoopSettings(
        dt_s=float(mpc.dt_s), n_steps=n_steps, speed_offset_left_mps=float(theta.dV),
        speed_offset_right_mps=float(theta.dV) * right_scale,
        speed_change_accel_mps2=float(scenario.speed_change_accel_mps2) if differ else 0.0,
        feedback_gain_radpm=float(theta.k), lookahead_m=float(scenario.lookahead_m),
        steer_limit_rad=float(mpc.steer_limit_rad), disturbance_gain=float(mpc.disturbance_gain),
        disturbance_start_gain=float(mpc.disturbance_start_gain),
        hold_steps=int(round(mpc.estimator_hold_s / mpc.dt_s)),
        estimator_uses_actuators=bool(mpc.estimator_uses_actuators),
        estimator_linear=mpc.estimator_model == "linear", model_steer_lag_s=float(mpc.model_steer_lag_s),
        c_lr=float(theta.c_lr), c_rl=float(theta.c_rl), settle_tolerance_rad=float(scenario.settle_tolerance_rad),
        left_circle=(float(left.center_x_m), float(left.center_y_m), float(left.radius_m)),
        right_circle=(float(right.center_x_m), float(right.center_y_m), float(right.radius_m)),
        max_sideslip_rad=float(failure.max_sideslip_rad), max_yaw_rate_radps=float(failure.max_yaw_rate_radps),
        max_lateral_error_m=float(failure.max_lateral_error_m), min_speed_mps=float(failure.min_speed_mps),
        gripup_sideslip_rad=float(failure.gripup_sideslip_rad), gripup_time_s=float(failure.gripup_time_s),
        gripup_grace_s=float(failure.gripup_grace_s), substep_s=float(config.plant.substep_s), noisy=bool(noisy),
        plant_kind=int(plant_kind), daqp_function=quadprog_address() if mpc.qp_solver == "daqp" else 0)
