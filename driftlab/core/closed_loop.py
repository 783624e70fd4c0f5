"""The closed loop of one episode, compiled: sensing, planner, controller and plant, control step by step.

Each control step (paper Algorithm 1, inner loop): the sensors read the plant (with the episode's noise), the
planner advances its phase on the tracked circle's trigger quantity c, the trajectory row and the failure
rules are written from the true state, the disturbance estimate is updated, and the MPC's increments are
formed. Where the unconstrained minimizer violates a limit (about one control step in twenty), the kernel solves the
QP with DAQP itself (:func:`solve_constrained`); with OSQP, :func:`run_until_constrained` returns to Python, which
solves it and hands the increments to :func:`finish_step`, and the loop then goes on.

A step is two halves, each a function: :func:`observe` (sensors, planner, row, failure rules: the world's half)
and :func:`control` with :func:`controller_commands` (the controller's half), the commands then sent and the plant
stepped (:func:`send_commands`, :func:`step_plant`). The episode runner (driftlab.core.episode) runs both halves;
the Gymnasium environment (driftlab.gym) runs the world's half with commands that a policy chose.

The arithmetic is that of the former step-by-step Python loop, operation for operation (``np.dot`` is the same
BLAS call as numpy's ``@``; :func:`driftlab.core.track.hypot` rounds as CPython does), so stored episodes
reproduce bit for bit (``tests/db/test_upgrade.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from driftlab.core.commonroad.plant import std_plant_step
from driftlab.core.controller import (
    DISTURBANCE_LIMIT,
    hold_estimate,
    lookahead_error_m,
    mirror,
    predict_one_step,
)
from driftlab.core.loop_reference import step_reference
from driftlab.core.loop_state import (
    C_BETA,
    C_BETA_REF,
    C_C,
    C_DELTA,
    C_DELTA_CMD,
    C_DELTA_MPC,
    C_DELTA_REF,
    C_DPSI,
    C_E,
    C_FXR,
    C_FXR_CMD,
    C_FXR_REF,
    C_OSQP,
    C_PHASE,
    C_PSI,
    C_R,
    C_R_REF,
    C_T,
    C_V,
    C_V_REF,
    C_X,
    C_Y,
    COMPLETED,
    DIVERGED,
    DONE,
    F_GRIPUP_SINCE_S,
    F_LAST_TRIGGER_S,
    F_SEEN_C,
    F_SEEN_DPSI,
    F_SEEN_E,
    GRIPPED_UP,
    I_DIRECTION,
    I_EVENTS,
    I_GRIPUP,
    I_HAS_LAST,
    I_HOLD_LEFT,
    I_LAST_DIRECTION,
    I_PLANT_DUE,
    I_ROWS,
    I_STATUS,
    I_STEP,
    I_UPDATES,
    LEFT_TRACK,
    MAX_EVENTS,
    N_SENSED,
    NEEDS_PLANT,
    NEEDS_QP,
    PHASE_FINISHED,
    REF_BOTH,
    REF_GAIN,
    REF_NONE,
    RUNNING,
    SOLVER_FAILED,
    SPUN_OUT,
    STALLED,
)
from driftlab.core.mpc import (
    KN,
    N_PER_KN,
    N_U,
    clip,
    constrained_terms,
    next_commands,
    pack_state,
    reference_gain_term,
    reference_linear_term,
    unconstrained_increments,
    update_estimate,
)
from driftlab.core.mpc.daqp_kernel import quadprog
from driftlab.core.planner import PLAN_PHASE, advance_phase, phase_direction
from driftlab.core.plant import (
    DRIVE,
    HEADING,
    PLANT_COMMONROAD_STD,
    PLANT_EXTERNAL,
    SIDESLIP,
    SPEED,
    STEER,
    X_POS,
    Y_POS,
    YAW_RATE,
    plant_step,
)
from driftlab.core.track import LEFT, circle_errors
from driftlab.core.variation import (
    NOISE_HEADING,
    NOISE_SIDESLIP,
    NOISE_SPEED,
    NOISE_X,
    NOISE_Y,
    NOISE_YAW_RATE,
)


@njit(cache=True)
def _errors(cfg, direction, x_m, y_m, course_rad):
    circle = cfg.left_circle if direction == LEFT else cfg.right_circle
    return circle_errors(circle[0], circle[1], circle[2], direction, x_m, y_m, course_rad)


@njit(cache=True)
def _failure(cfg, st, t_s, s, lateral_error_m, beta_ref_rad):
    """The failure rules (:class:`~driftlab.core.config.FailureLimits`) on the true state: a status or RUNNING."""
    if not np.all(np.isfinite(s)) or not np.isfinite(lateral_error_m):
        return DIVERGED
    if abs(s[SIDESLIP]) > cfg.max_sideslip_rad or abs(s[YAW_RATE]) > cfg.max_yaw_rate_radps:
        return SPUN_OUT
    if abs(lateral_error_m) > cfg.max_lateral_error_m:
        return LEFT_TRACK
    if s[SPEED] < cfg.min_speed_mps:
        return STALLED
    drifting = s[SIDESLIP] * beta_ref_rad > 0.0 and abs(s[SIDESLIP]) >= cfg.gripup_sideslip_rad
    if drifting or t_s - st.floats[F_LAST_TRIGGER_S] < cfg.gripup_grace_s:
        st.ints[I_GRIPUP] = 0
    elif st.ints[I_GRIPUP] == 0:
        st.ints[I_GRIPUP] = 1
        st.floats[F_GRIPUP_SINCE_S] = t_s
    elif t_s - st.floats[F_GRIPUP_SINCE_S] > cfg.gripup_time_s:
        return GRIPPED_UP
    return RUNNING


@njit(cache=True)
def _update_disturbance(cfg, st, qa_last, params, measured, actuators, direction, frozen):
    """The disturbance estimate after this step's measurement, mirrored to the side driven (offset-free MPC;
    zero when off)."""
    if st.ints[I_HAS_LAST] == 0 or cfg.disturbance_gain == 0.0:
        return st.estimate.copy()
    if not frozen:
        # One-step prediction under the inputs the actuators actually applied (measured at both ends of the
        # step, shaped by the model's lag).
        if cfg.estimator_uses_actuators:
            start, end, lag = st.last_actuators, actuators, cfg.model_steer_lag_s
        else:
            start, end, lag = st.last_applied, st.last_applied, 0.0
        predicted = predict_one_step(qa_last, params, cfg.estimator_linear, st.last_measured, start, end, lag,
                                     cfg.dt_s)
        update_estimate(st.estimate, st.ints[I_UPDATES:I_UPDATES + 1], (measured - predicted) * mirror(direction),
                        cfg.disturbance_gain, cfg.disturbance_start_gain, cfg.dt_s, DISTURBANCE_LIMIT)
    return st.estimate * mirror(direction)


@njit(cache=True)
def _sensed(cfg, s, noise_row):
    """The plant state as the sensors report it: pose and [V, beta, r] with this step's noise."""
    if not cfg.noisy:
        return s
    sensed = s.copy()
    sensed[X_POS] += noise_row[NOISE_X]
    sensed[Y_POS] += noise_row[NOISE_Y]
    sensed[HEADING] += noise_row[NOISE_HEADING]
    sensed[SPEED] += noise_row[NOISE_SPEED]
    sensed[SIDESLIP] += noise_row[NOISE_SIDESLIP]
    sensed[YAW_RATE] += noise_row[NOISE_YAW_RATE]
    return sensed


@njit(cache=True)
def observe(cfg, st, qa_left, qa_right, noise):
    """The sensing half of a control step (paper Algorithm 1, inner loop): the sensors read the plant, the planner
    advances its phase, the trajectory row is written from the true state and the failure rules judge it.

    Leaves what the controller reads in ``st.sensed`` and ``st.floats[F_SEEN_*]``. Returns RUNNING, a failure
    status, COMPLETED (the 8 finished) or, past ``cfg.n_steps``, STALLED (out of time); the status is also set in
    ``st.ints[I_STATUS]`` unless RUNNING."""
    ints, floats = st.ints, st.floats
    if ints[I_STEP] > cfg.n_steps:
        ints[I_STATUS] = STALLED  # out of time before finishing the 8
        return STALLED
    step = ints[I_STEP]
    t = step * cfg.dt_s
    s = st.plant
    sensed = _sensed(cfg, s, noise[step])
    phase = int(st.plan[PLAN_PHASE])
    direction = phase_direction(phase)
    seen = _errors(cfg, direction, sensed[X_POS], sensed[Y_POS], sensed[HEADING] + sensed[SIDESLIP])
    ref = step_reference(cfg, st, qa_left, qa_right, direction)
    phase, changed = advance_phase(st.plan, seen[3], sensed[SIDESLIP] - ref[1], cfg.c_lr, cfg.c_rl,
                                   cfg.settle_tolerance_rad)
    if changed and ints[I_EVENTS] < MAX_EVENTS:
        event = st.events[ints[I_EVENTS]]
        event[0], event[1], event[2], event[3] = t, phase, sensed[X_POS], sensed[Y_POS]
        ints[I_EVENTS] += 1
    if phase != PHASE_FINISHED and phase_direction(phase) != direction:
        direction = phase_direction(phase)
        seen = _errors(cfg, direction, sensed[X_POS], sensed[Y_POS], sensed[HEADING] + sensed[SIDESLIP])
        ref = step_reference(cfg, st, qa_left, qa_right, direction)
        floats[F_LAST_TRIGGER_S] = t
    errors = _errors(cfg, direction, s[X_POS], s[Y_POS], s[HEADING] + s[SIDESLIP]) if cfg.noisy else seen
    row = st.rows[ints[I_ROWS]]
    row[C_T] = t
    row[C_X], row[C_Y], row[C_PSI] = s[X_POS], s[Y_POS], s[HEADING]
    row[C_V], row[C_BETA], row[C_R] = s[SPEED], s[SIDESLIP], s[YAW_RATE]
    row[C_DELTA], row[C_FXR] = s[STEER], s[DRIVE]
    row[C_E], row[C_DPSI], row[C_C] = errors[0], errors[1], errors[3]
    row[C_PHASE] = phase
    row[C_V_REF], row[C_BETA_REF], row[C_R_REF] = ref[0], ref[1], ref[2]
    row[C_DELTA_REF], row[C_FXR_REF] = ref[3], ref[4] * N_PER_KN
    ints[I_ROWS] += 1
    st.sensed[:] = sensed[:N_SENSED]
    floats[F_SEEN_E], floats[F_SEEN_DPSI], floats[F_SEEN_C] = seen[0], seen[1], seen[3]
    failure = _failure(cfg, st, t, s, errors[0], ref[1])
    if failure != RUNNING:
        ints[I_STATUS] = failure
        return failure
    if phase == PHASE_FINISHED:
        ints[I_STATUS] = COMPLETED
        return COMPLETED
    return RUNNING


@njit(cache=True)
def control(cfg, st, qa_left, qa_right, model_params):
    """The controller's half of a control step, after :func:`observe`: the disturbance estimate, the reference and
    the MPC's unconstrained increments. Returns (du, within); where ``within`` is False a limit is active and
    the QP's terms of the step are in ``st.qp_*`` (the increments are then the QP's solution, :func:`finish_step`)."""
    ints, floats = st.ints, st.floats
    s, sensed = st.plant, st.sensed
    phase = int(st.plan[PLAN_PHASE])
    direction = phase_direction(phase)
    in_flick = not (phase == 0 or phase == 2 or phase == 4)
    frozen, ints[I_HOLD_LEFT] = hold_estimate(in_flick, ints[I_HOLD_LEFT], cfg.hold_steps)
    measured = np.array([sensed[SPEED], sensed[SIDESLIP], sensed[YAW_RATE]])
    actuators = np.array([s[STEER], s[DRIVE]])
    ints[I_LAST_DIRECTION] = ints[I_DIRECTION]
    ints[I_DIRECTION] = direction
    qa_last = qa_left if ints[I_LAST_DIRECTION] == LEFT else qa_right
    disturbance = _update_disturbance(cfg, st, qa_last, model_params, measured, actuators, direction, frozen)
    qa = qa_left if direction == LEFT else qa_right
    side = 0 if direction == LEFT else 1
    z_now = pack_state(qa.path_states, qa.models_lag, measured, np.array([floats[F_SEEN_E], floats[F_SEEN_DPSI]]),
                       np.array([actuators[0], actuators[1] * KN]),
                       np.array([st.last_mpc[0], st.last_mpc[1] * KN]))
    z_ref = step_reference(cfg, st, qa_left, qa_right, direction)
    if st.ref_valid[side] == REF_NONE or np.any(st.ref_key[side] != z_ref):
        st.ref_gain[side] = reference_gain_term(qa, z_ref)
        st.ref_key[side] = z_ref
        st.ref_valid[side] = REF_GAIN  # the QP's linear term waits for a step with an active limit
    du, dz, offset, within = unconstrained_increments(qa, z_now, st.ref_gain[side], disturbance)
    st.last_measured[:] = measured
    st.last_actuators[:] = actuators
    ints[I_HAS_LAST] = 1
    st.pending[:] = z_now[-N_U:]
    if not within:
        if st.ref_valid[side] == REF_GAIN:  # of the reference the gain term was computed for
            st.ref_linear[side] = reference_linear_term(qa, st.ref_key[side])
            st.ref_valid[side] = REF_BOTH
        q, lower, upper = constrained_terms(qa, dz, disturbance, st.ref_linear[side], offset)
        st.qp_q[:], st.qp_lower[:], st.qp_upper[:] = q, lower, upper
    return du, within


@njit(cache=True)
def run_until_constrained(cfg, st, qa_left, qa_right, model_params, plant_params, actuator_params, noise):
    """Steps the loop until the episode ends (returns DONE, the status in ``st.ints[I_STATUS]``) or, where OSQP
    solves (``cfg.daqp_function`` 0), a step's QP has an active limit (returns NEEDS_QP with the QP's terms in
    ``st.qp_*``; call :func:`finish_step`). With DAQP the kernel solves such a step itself."""
    while True:
        if observe(cfg, st, qa_left, qa_right, noise) != RUNNING:
            return DONE
        du, within = control(cfg, st, qa_left, qa_right, model_params)
        qa = qa_left if st.ints[I_DIRECTION] == LEFT else qa_right
        if within:
            finish_step(cfg, st, qa, plant_params, actuator_params, du, True, False)
        elif cfg.daqp_function != 0:
            du, ok = solve_constrained(cfg, st, qa)
            finish_step(cfg, st, qa, plant_params, actuator_params, du, ok, True)
        else:
            return NEEDS_QP
        if st.ints[I_STATUS] != RUNNING:
            return DONE
        if st.ints[I_PLANT_DUE] == 1:
            return NEEDS_PLANT


@njit(cache=True)
def solve_constrained(cfg, st, qa):
    """(du, ok) of this step's constrained QP (its terms in ``st.qp_*``) by DAQP, as
    :meth:`driftlab.core.mpc.QpSession.solve_constrained` returns them: du within the step limits, zero where the
    solver failed."""
    exitflag = quadprog(cfg.daqp_function, qa.hessian, st.qp_q, qa.cumsum, st.qp_upper, st.qp_lower, qa.daqp_sense,
                        st.qp_x, st.qp_lam, st.daqp_problem, st.daqp_result, st.daqp_settings)
    if exitflag <= 0 or not np.all(np.isfinite(st.qp_x)):
        return np.zeros(qa.step_limit.shape[0]), False
    return np.clip(st.qp_x, -qa.step_limit, qa.step_limit), True


@njit(cache=True)
def controller_commands(cfg, st, qa, du, used_osqp):
    """(steer rad, drive N) the controller sends once its increments are known: the MPC's commands and the paper's
    steering feedback delta_f = delta_mpc + k e_la (eq. 11); notes the MPC's own in the row."""
    steer_mpc, drive_kn = next_commands(qa, st.pending, du)
    drive_n = drive_kn / KN
    st.last_mpc[0], st.last_mpc[1] = steer_mpc, drive_n
    e_la = lookahead_error_m(st.floats[F_SEEN_E], st.floats[F_SEEN_DPSI], cfg.lookahead_m)
    steer = clip(steer_mpc + cfg.feedback_gain_radpm * e_la, -cfg.steer_limit_rad, cfg.steer_limit_rad)
    row = st.rows[st.ints[I_ROWS] - 1]
    row[C_DELTA_MPC] = steer_mpc
    row[C_OSQP] = 1.0 if used_osqp else 0.0
    return steer, drive_n


@njit(cache=True)
def send_commands(st, steer_rad, drive_n):
    """The commands sent this step, noted in the loop and its row."""
    st.last_applied[0], st.last_applied[1] = steer_rad, drive_n
    row = st.rows[st.ints[I_ROWS] - 1]
    row[C_DELTA_CMD], row[C_FXR_CMD] = steer_rad, drive_n


@njit(cache=True)
def step_plant(cfg, st, plant_params, actuator_params):
    """The plant's step under the commands sent (zero-order hold over dt); the loop moves to the next step."""
    steer, drive_n = st.last_applied[0], st.last_applied[1]
    if cfg.plant_kind == PLANT_COMMONROAD_STD:  # stepped here: a return to Python per step costs it 1.5x
        st.plant[:] = std_plant_step(st.plant, steer, drive_n, cfg.dt_s, cfg.substep_s, plant_params,
                                     actuator_params)
    elif cfg.plant_kind == PLANT_EXTERNAL:
        # Another plant (CommonRoad's MB, a registered one): the caller steps it with st.last_applied. Kept out of
        # this kernel, so that its first compile does not grow with every plant (MB's derivatives alone ~10 s).
        st.ints[I_PLANT_DUE] = 1
    else:
        st.plant[:] = plant_step(st.plant, steer, drive_n, cfg.dt_s, cfg.substep_s, plant_params, actuator_params)
    st.ints[I_STEP] += 1


@njit(cache=True)
def finish_step(cfg, st, qa, plant_params, actuator_params, du, ok, used_osqp):
    """The rest of a control step once its increments are known: commands (:func:`controller_commands`) and the
    plant's step; a failed solve ends the episode before the plant moves."""
    steer, drive_n = controller_commands(cfg, st, qa, du, used_osqp)
    send_commands(st, steer, drive_n)
    if not ok:
        st.ints[I_STATUS] = SOLVER_FAILED
        return
    step_plant(cfg, st, plant_params, actuator_params)
