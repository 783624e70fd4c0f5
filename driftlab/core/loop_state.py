"""The closed loop's state, as the compiled kernels read it (driftlab.core.closed_loop): the trajectory's columns,
the status and return codes, the episode's constants (:class:`LoopSettings`) and everything that changes during an
episode (:class:`LoopState`), arrays the kernels update in place."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from driftlab.core.mpc.daqp_kernel import PROBLEM_WORDS, RESULT_WORDS, SETTINGS_WORDS
from driftlab.core.mpc_config import N_U
from driftlab.core.planner import Phase
from driftlab.core.plant import N_PLANT_STATES
from driftlab.core.statuses import EpisodeStatus
from driftlab.core.track import LEFT

# Trajectory columns recorded at the controller rate, with units.
COLUMNS = (
    "t_s", "x_m", "y_m", "psi_rad", "V_mps", "beta_rad", "r_radps", "delta_cmd_rad", "delta_rad", "delta_mpc_rad",
    "Fxr_cmd_n", "Fxr_n", "e_m", "dpsi_rad", "c", "phase", "V_ref_mps", "beta_ref_rad", "r_ref_radps",
    "delta_ref_rad", "Fxr_ref_n", "osqp",
)
COL = {name: i for i, name in enumerate(COLUMNS)}
(C_T, C_X, C_Y, C_PSI, C_V, C_BETA, C_R, C_DELTA_CMD, C_DELTA, C_DELTA_MPC, C_FXR_CMD, C_FXR, C_E, C_DPSI, C_C,
 C_PHASE, C_V_REF, C_BETA_REF, C_R_REF, C_DELTA_REF, C_FXR_REF, C_OSQP) = range(len(COLUMNS))


STATUSES = tuple(EpisodeStatus)
(COMPLETED, SPUN_OUT, LEFT_TRACK, STALLED, GRIPPED_UP, SOLVER_FAILED, DIVERGED, REFUSED, INVALID) = range(
    len(STATUSES))
RUNNING = -1

# What run_until_constrained returns.
DONE, NEEDS_QP, NEEDS_PLANT = 0, 1, 2

# Integer loop state: step, rows written, controller's direction and last direction, hold steps left,
# whether a previous measurement exists, status, trigger events, the grip-up clock's state.
(I_STEP, I_ROWS, I_DIRECTION, I_LAST_DIRECTION, I_HOLD_LEFT, I_HAS_LAST, I_STATUS, I_EVENTS, I_GRIPUP,
 I_UPDATES, I_PLANT_DUE) = range(11)
# Float loop state: last trigger time, grip-up start, this step's path errors as sensed (e m, dpsi rad, c), which the
# controller reads.
F_LAST_TRIGGER_S, F_GRIPUP_SINCE_S, F_SEEN_E, F_SEEN_DPSI, F_SEEN_C = range(5)
N_SENSED = N_PLANT_STATES  # what the sensors report: the loop's eight plant states
MAX_EVENTS = 40  # 4 phase changes a lap, MAX_LAPS laps, and the finish

# What LoopState.ref_valid says of a side's cached reference terms: none yet, the minimizer's gain term (every step
# needs it), or that and the QP's linear term (only a step with an active limit needs it).
REF_NONE, REF_GAIN, REF_BOTH = 0, 1, 2

PHASE_FINISHED = int(Phase.FINISHED)  # a plain int: a compile-time constant in the kernels


class LoopSettings(NamedTuple):
    """The episode's constants the compiled loop reads (theta, scenario, controller, failure rules)."""

    dt_s: float
    n_steps: int
    speed_offset_left_mps: float  # dV on each circle (scaled by its drift speed where the radii differ)
    speed_offset_right_mps: float
    speed_change_accel_mps2: float  # > 0: the planned speed change before a flick (see driftlab.core.loop_reference)
    feedback_gain_radpm: float
    lookahead_m: float
    steer_limit_rad: float
    disturbance_gain: float
    disturbance_start_gain: float
    hold_steps: int
    estimator_uses_actuators: bool
    estimator_linear: bool
    model_steer_lag_s: float
    c_lr: float
    c_rl: float
    settle_tolerance_rad: float
    left_circle: tuple[float, float, float]  # centre x, centre y, radius [m]
    right_circle: tuple[float, float, float]
    max_sideslip_rad: float
    max_yaw_rate_radps: float
    max_lateral_error_m: float
    min_speed_mps: float
    gripup_sideslip_rad: float
    gripup_time_s: float
    gripup_grace_s: float
    substep_s: float
    noisy: bool
    plant_kind: int  # PLANT_DRIFTLAB or PLANT_COMMONROAD_STD (stepped in the kernel) or PLANT_EXTERNAL
    daqp_function: int  # daqp_quadprog's address: the kernel solves a constrained step itself (0: OSQP, in Python)


class LoopState(NamedTuple):
    """Everything that changes during an episode, as arrays the compiled loop updates in place."""

    ints: np.ndarray
    floats: np.ndarray
    plant: np.ndarray  # the plant state (driftlab.core.plant layout)
    sensed: np.ndarray  # this step's plant state as the sensors report it (the loop's eight, X_POS ... DRIVE)
    plan: np.ndarray  # the planner's state (driftlab.core.planner layout)
    estimate: np.ndarray  # disturbance estimate on (Vdot, betadot, rdot), left-hand form
    last_mpc: np.ndarray  # the MPC's last commands [delta rad, Fxr N]
    last_applied: np.ndarray  # the last commands sent [delta rad, Fxr N]
    last_measured: np.ndarray  # the last measured [V, beta, r]
    last_actuators: np.ndarray  # the last measured actuator positions [delta rad, Fxr N]
    ref_key: np.ndarray  # (2, 5): the reference each side's cached terms belong to
    ref_gain: np.ndarray  # (2, 2 Nc): cached reference terms per side (index 0 left, 1 right)
    ref_linear: np.ndarray
    ref_valid: np.ndarray  # REF_NONE, REF_GAIN or REF_BOTH per side
    rows: np.ndarray  # (n_steps + 1, len(COLUMNS))
    events: np.ndarray  # (MAX_EVENTS, 4): t s, phase, x m, y m of each phase change
    pending: np.ndarray  # the step waiting for its constrained QP: [u_prev (2)]
    qp_q: np.ndarray  # that QP's terms (DAQP's or OSQP's)
    qp_lower: np.ndarray
    qp_upper: np.ndarray
    ref_memo: np.ndarray  # the last reference computed (5; driftlab.core.loop_reference)
    ref_memo_key: np.ndarray  # its inputs: [direction (0: none yet), offset m/s, estimate (3)]
    qp_x: np.ndarray  # DAQP's solution and multipliers of that step, where the kernel solves it
    qp_lam: np.ndarray
    daqp_problem: np.ndarray  # DAQP's C structs, as 64-bit words (driftlab.core.mpc.daqp_kernel)
    daqp_result: np.ndarray
    daqp_settings: np.ndarray


def new_loop_state(plant_state: np.ndarray, plan: np.ndarray, start_inputs: np.ndarray, n_steps: int,
                   n_increments: int) -> LoopState:
    ints = np.zeros(11, dtype=np.int64)
    ints[I_DIRECTION] = ints[I_LAST_DIRECTION] = LEFT
    ints[I_STATUS] = RUNNING
    return LoopState(ints=ints, floats=np.zeros(5), plant=plant_state.copy(), sensed=np.zeros(N_SENSED),
                     plan=plan, estimate=np.zeros(3), last_mpc=start_inputs.copy(),
                     last_applied=start_inputs.copy(), last_measured=np.zeros(3), last_actuators=np.zeros(2),
                     ref_key=np.zeros((2, 5)), ref_gain=np.zeros((2, n_increments)),
                     ref_linear=np.zeros((2, n_increments)), ref_valid=np.zeros(2, dtype=np.int64),
                     rows=np.zeros((n_steps + 1, len(COLUMNS))), events=np.zeros((MAX_EVENTS, 4)),
                     pending=np.zeros(N_U), qp_q=np.zeros(n_increments), qp_lower=np.zeros(2 * n_increments),
                     qp_upper=np.zeros(2 * n_increments), ref_memo=np.zeros(5), ref_memo_key=np.zeros(5),
                     qp_x=np.zeros(n_increments),
                     qp_lam=np.zeros(2 * n_increments), daqp_problem=np.zeros(PROBLEM_WORDS, dtype=np.int64),
                     daqp_result=np.zeros(RESULT_WORDS, dtype=np.int64),
                     daqp_settings=np.zeros(SETTINGS_WORDS, dtype=np.int64))
