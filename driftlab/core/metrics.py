"""Episode metrics and the paper's objective J (eq. 12)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
from numba import njit

from driftlab.core.planner import Phase, phase_direction
from driftlab.core.track import LEFT, FigureEight, wrap_angle

COURSE_WEIGHT = 5.0  # lambda_1 (paper section IV-A)
SIDESLIP_WEIGHT = 1.0  # lambda_2
SUSTAINED_PHASES = (Phase.LEFT_DRIFT, Phase.RIGHT_DRIFT, Phase.LEFT_DRIFT_FINAL)


@dataclass(frozen=True)
class EpisodeMetrics:
    objective_j: float  # log(mean(|e| + 5 |dpsi| + |beta - beta_ref|)) over every step
    completed_fraction: float  # share of the 8's length driven, [0, 1]
    mean_abs_e_m: float
    max_abs_e_m: float
    mean_abs_beta_err_rad: float  # sustained phases only
    beta_flip_s: list[float]  # per transition: trigger to beta changing sign
    beta_settle_s: list[float]  # per transition: trigger to |beta - beta_ref| < the scenario's settle tolerance
    min_speed_mps: float
    max_abs_yaw_rate_radps: float
    trigger_times_s: list[float]
    duration_s: float
    lap_mean_abs_e_m: list[float]  # mean |e| over each lap of the 8 driven (by arc length; the last may be partial)
    # Each run of one planner phase in order (:func:`phase_segments`): the drifts and the flicks in numbers.
    phases: list[dict] = field(default_factory=list)
    # Why an episode stopped before its first step (the controller's model has no drift to hold), else None.
    failure_reason: str | None = None
    # Where the plant left its model's validity, if it reports it (MB: time with a negative wheel load).
    plant_validity: dict | None = None

    def as_dict(self) -> dict:
        out = asdict(self)
        out.pop("objective_j")
        return out


def objective_j(e_m: np.ndarray, dpsi_rad: np.ndarray, beta_err_rad: np.ndarray) -> float:
    """J = log(mean_k(|e_k| + 5 |dpsi_k| + |beta_k - beta_eq|)) (paper eq. 12)."""
    cost = np.abs(e_m) + COURSE_WEIGHT * np.abs(dpsi_rad) + SIDESLIP_WEIGHT * np.abs(beta_err_rad)
    return objective_of_costs(cost)


def objective_of_costs(stage_costs: np.ndarray | list[float]) -> float:
    """J from the stage costs of every step (:func:`stage_cost`, in order): log of their mean (paper eq. 12)."""
    return float(math.log(max(float(np.mean(stage_costs)), 1e-12)))


@njit(cache=True)
def stage_cost(e_m, dpsi_rad, beta_err_rad):
    """One step's term of J: |e| + 5 |dpsi| + |beta - beta_eq| (paper eq. 12), rounded as :func:`objective_j`
    rounds it."""
    return abs(e_m) + COURSE_WEIGHT * abs(dpsi_rad) + SIDESLIP_WEIGHT * abs(beta_err_rad)


def cumulative_progress_m(traj: np.ndarray, track: FigureEight, col: dict[str, int]) -> np.ndarray:
    """Arc length driven up to each step (0 at the first)."""
    left, right = track.left, track.right
    return _cumulative_progress_m(np.ascontiguousarray(traj[:, col["x_m"]]),
                                  np.ascontiguousarray(traj[:, col["y_m"]]),
                                  np.ascontiguousarray(traj[:, col["phase"]]), left.center_y_m, left.radius_m,
                                  right.center_y_m, right.radius_m)


@njit(cache=True)
def _cumulative_progress_m(x_m, y_m, phase, left_center_y_m, left_radius_m, right_center_y_m, right_radius_m):
    cumulative = np.zeros(len(x_m))
    total = 0.0
    for i in range(1, len(x_m)):
        direction = phase_direction(int(phase[i]))
        center_y, radius = (left_center_y_m, left_radius_m) if direction == LEFT else (right_center_y_m,
                                                                                         right_radius_m)
        a0 = math.atan2(y_m[i - 1] - center_y, x_m[i - 1] - 0.0)
        a1 = math.atan2(y_m[i] - center_y, x_m[i] - 0.0)
        total += direction * wrap_angle(a1 - a0) * radius
        cumulative[i] = total
    return cumulative


def lap_of_steps(cumulative_m: np.ndarray, track: FigureEight) -> np.ndarray:
    """The lap (0, 1, ...) each step is on, cut by the arc length driven (one lap = ``track.lap_length_m``)."""
    driven_m = np.nan_to_num(np.maximum(cumulative_m, 0.0), nan=0.0)  # a diverged step (NaN) counts as lap 0
    return np.minimum((driven_m // track.lap_length_m).astype(int), track.laps - 1)


def laps_of_rows(rows: np.ndarray, columns: dict[str, int], track: FigureEight) -> np.ndarray:
    """The lap (1, 2, ...) each trajectory row is on: what the downloads' ``lap`` column, the plots and the view
    show (cut by arc length as :func:`lap_of_steps`)."""
    if len(rows) == 0:
        return np.zeros(0, dtype=int)
    return lap_of_steps(cumulative_progress_m(rows, track, columns), track) + 1


def lap_mean_abs_e_m(e_m: np.ndarray, cumulative_m: np.ndarray, track: FigureEight) -> list[float]:
    """Mean |e| over each lap of the 8 driven."""
    lap = lap_of_steps(cumulative_m, track)
    return [float(np.mean(np.abs(e_m[lap == i]))) for i in range(int(lap.max()) + 1) if np.any(lap == i)]


def _transition_times(t: np.ndarray, beta: np.ndarray, beta_ref: np.ndarray, trigger_s: float,
                      tolerance: float) -> tuple[float, float]:
    after = t >= trigger_s
    flipped = after & (beta * beta_ref > 0)
    settled = after & (np.abs(beta - beta_ref) < tolerance)
    flip = float(t[np.argmax(flipped)] - trigger_s) if flipped.any() else math.nan
    settle = float(t[np.argmax(settled)] - trigger_s) if settled.any() else math.nan
    return flip, settle


def phase_segments(t_s: np.ndarray, phase: np.ndarray, e_m: np.ndarray, beta_err_rad: np.ndarray,
                   speed_mps: np.ndarray, beta_rad: np.ndarray, steer_rad: np.ndarray,
                   beta_ref_rad: np.ndarray, settle_tolerance_rad: float = 0.05) -> list[dict]:
    """Each run of one planner phase (paper section III-A: sustained drift, inertia drift, ...), in order, the
    finish excluded: its name, start and end [s] (the end is the next run's start), mean and max |e| [m], mean and
    RMS |beta - beta_ref| [rad], the share of its steps steered against the turn (countersteer: the steering angle
    has the sideslip's sign), speed at its start, its lowest speed and the loss between them [m/s]. A flick's
    (``inertia_*``) runs from its trigger to the sideslip settling on the new side, so its speed loss is the
    "minimal velocity loss" the paper claims for the inertia drift; a flick also gives the time from its trigger
    to the sideslip changing sign (``flip_s``) and to it settling within the scenario's tolerance of the new
    reference (``settle_s``; None where it never did)."""
    starts = [0, *(int(i) + 1 for i in np.flatnonzero(np.diff(phase)))]  # Python ints: the metrics are JSON
    ends = [*starts[1:], len(t_s)]
    segments = []
    for start, end in zip(starts, ends, strict=True):
        if phase[start] == Phase.FINISHED:
            continue
        run = slice(start, end)
        lowest = float(np.min(speed_mps[run]))
        segment = {
            "phase": Phase(int(phase[start])).name.lower(), "start_s": float(t_s[start]),
            "end_s": float(t_s[end] if end < len(t_s) else t_s[-1]), "steps": end - start,
            "mean_abs_e_m": float(np.mean(np.abs(e_m[run]))), "max_abs_e_m": float(np.max(np.abs(e_m[run]))),
            "mean_abs_beta_err_rad": float(np.mean(np.abs(beta_err_rad[run]))),
            "rms_beta_err_rad": float(np.sqrt(np.mean(beta_err_rad[run] ** 2))),
            "countersteer_share": float(np.mean(steer_rad[run] * beta_rad[run] > 0.0)),
            "start_speed_mps": float(speed_mps[start]), "min_speed_mps": lowest,
            "speed_loss_mps": float(speed_mps[start]) - lowest}
        if Phase(int(phase[start])) in (Phase.INERTIA_LEFT_TO_RIGHT, Phase.INERTIA_RIGHT_TO_LEFT):
            flip, settle = _transition_times(t_s, beta_rad, beta_ref_rad, float(t_s[start]), settle_tolerance_rad)
            segment["flip_s"] = None if math.isnan(flip) else flip
            segment["settle_s"] = None if math.isnan(settle) else settle
        segments.append(segment)
    return segments


def compute_metrics(traj: np.ndarray, trigger_times_s: list[float], track: FigureEight,
                    col: dict[str, int], settle_tolerance_rad: float = 0.05) -> EpisodeMetrics:
    """``settle_tolerance_rad``: the scenario's, so that beta_settle_s means what ends an inertia phase."""
    if len(traj) == 0:
        return EpisodeMetrics(math.log(1e3), 0.0, math.nan, math.nan, math.nan, [], [], math.nan, math.nan, [], 0.0,
                              [])
    t = traj[:, col["t_s"]]
    e = traj[:, col["e_m"]]
    beta = traj[:, col["beta_rad"]]
    beta_ref = traj[:, col["beta_ref_rad"]]
    phase = traj[:, col["phase"]].astype(int)
    beta_err = beta - beta_ref
    finished = phase[-1] == Phase.FINISHED
    # An unfinished run never counts as whole, however far it went round.
    cumulative = cumulative_progress_m(traj, track, col)
    driven = float(cumulative[-1]) / track.scenario_length_m
    fraction = 1.0 if finished else min(max(driven, 0.0), 0.99)
    sustained = np.isin(phase, [int(p) for p in SUSTAINED_PHASES])
    flips, settles = [], []
    for trigger in trigger_times_s:
        flip, settle = _transition_times(t, beta, beta_ref, trigger, settle_tolerance_rad)
        flips.append(flip)
        settles.append(settle)
    return EpisodeMetrics(
        objective_j=objective_j(e, traj[:, col["dpsi_rad"]], beta_err),
        completed_fraction=float(fraction),
        mean_abs_e_m=float(np.mean(np.abs(e))),
        max_abs_e_m=float(np.max(np.abs(e))),
        mean_abs_beta_err_rad=float(np.mean(np.abs(beta_err[sustained]))) if sustained.any() else math.nan,
        beta_flip_s=flips,
        beta_settle_s=settles,
        min_speed_mps=float(np.min(traj[:, col["V_mps"]])),
        max_abs_yaw_rate_radps=float(np.max(np.abs(traj[:, col["r_radps"]]))),
        trigger_times_s=[float(x) for x in trigger_times_s],
        duration_s=float(t[-1]),
        lap_mean_abs_e_m=lap_mean_abs_e_m(e, cumulative, track),
        phases=phase_segments(t, phase, e, beta_err, traj[:, col["V_mps"]], beta, traj[:, col["delta_rad"]],
                              beta_ref, settle_tolerance_rad),
    )
