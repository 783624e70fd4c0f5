"""The linear MPC drift controller (paper section II-B), condensed and solved with OSQP.

Augmented state z = [V, beta, r, delta, Fxr] with Fxr in kN (in newtons OSQP needs thousands of iterations,
REFERENCE.md section 4), inputs the increments [d_delta, d_Fxr]. The model is linearized about the reference
drift equilibrium and discretized (forward Euler as in the paper, or exact zero-order hold). Cost:
sum_{k=1..Np} ||z_k - z_ref||_Q^2 + sum_{k=0..Nc-1} ||du_k||_R^2 (paper eq. 7), Np = Nc, box limits on
delta, Fxr and both increments.

Solving: the QP is condensed to the 2*Nc increments once per reference. Each step first forms the
unconstrained minimizer with a precomputed gain; when it satisfies every limit it *is* the QP's solution
(the constraints are inactive, the QP is strictly convex). Only otherwise (about one step in twenty) a solver
runs, chosen by ``qp_solver``:

- ``daqp`` (default): DAQP's dual active-set method (Arnstroem, Bemporad & Axehill 2022), exact for this dense
  40-variable QP, ~60 us a solve with the call.
- ``osqp``: OSQP (the paper's solver; set up once per episode, warm-started within it, only q, l, u updated) at
  ``osqp_eps``, ~600 us a solve. Its accepted answers include "solved inaccurate": on the default plant they
  sat up to 0.64 (rad or kN) from the exact increments, some beyond a limit. Jobs stored before revision 7
  ran it and stay on it. OSQP's polishing is off: OSQP 1.x prints an unguarded line on stdout per polish
  (osqp/osqp#785), which would corrupt the CLI's JSON.

Offset-free extension (not in the paper; ``disturbance_gain`` > 0): a constant additive disturbance d on
(Vdot, betadot, rdot) is estimated each step from the difference between the measured state and the
controller model's one-step prediction, and enters the prediction (Maeder, Borrelli & Morari 2009).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import NamedTuple

import daqp
import numpy as np
import scipy.linalg
from numba import njit

from driftlab.core.equilibrium import Equilibrium, jacobians
from driftlab.core.errors import ConfigError
from driftlab.core.validation import check_ranges

KN = 1e-3  # the QP's drive-force unit is kN
N_X = 3
N_U = 2
N_Z = N_X + N_U


@dataclass(frozen=True)
class MpcConfig:
    """Controller settings. The defaults are DriftLab's formulation; :meth:`paper` is the paper's.

    Default ("extended"): the paper's linear MPC plus what the mismatched default plant needs: lateral and
    course errors as model states (path_states), first-order actuator lags in the model, exact (ZOH)
    discretization, and weights from a random search on the default plant (benchmarks/tune_weights.py; the
    defaults are its best set, rounded).
    Paper: 3-state model linearized at the target, Euler, REFERENCE.md section 7's weights.

    Attributes:
        dt_s: sampling time [s].
        horizon: Np = Nc [steps].
        q_speed, q_sideslip, q_yaw_rate, q_steer, q_drive_kn: state weights Q for [V, beta, r, delta, Fxr kN].
        r_steer_step, r_drive_step_kn: increment weights R for [d_delta, d_Fxr kN].
        steer_limit_rad: |delta| limit [rad].
        drive_min_n, drive_max_n: Fxr limits [N].
        steer_rate_radps: |d_delta| / dt limit [rad/s].
        drive_rate_nps: |d_Fxr| / dt limit [N/s].
        discretization: "euler" (the paper) or "zoh" (exact for the linear model).
        disturbance_gain: filter gain in [0, 1] of the offset-free disturbance estimate (0: the paper).
        model_steer_lag_s, model_drive_lag_s: actuator time constants the controller's model assumes [s];
            both 0 is the paper's model (inputs act at once).
        qp_solver: "daqp" (exact dual active set) or "osqp" (the paper's; stored jobs before schema 7).
        osqp_eps: OSQP absolute and relative tolerance.
        path_states: add e [m] and dpsi [rad] to the model (False: the paper).
        q_lateral_error, q_course_error: weights on e and dpsi when path_states is on.
        terminal_cost: weigh the last predicted state with the Riccati cost-to-go.
        disturbance_start_gain: the estimate starts as a running mean whose gain is capped at this (see
            :func:`update_estimate`); 0 starts at ``disturbance_gain``.
        estimator_hold_s: the disturbance estimate stays frozen this long after an inertia phase ends [s]
            (the flick's aftermath is far from the drift whose mismatch it estimates).
        estimator_uses_actuators: the estimate's one-step prediction takes the measured actuator positions
            (False: the commands sent, as releases before schema 5 did).
        estimator_model: "linear" (the MPC's own linearization: the estimate absorbs its linearization error
            too, which makes the tracking offset-free) or "nonlinear" (the 3-state model, schema < 5).
        feedback_in_model: the MPC's model knows that k e_la is added to its steering (needs path_states);
            without it the MPC sees that feedback as a disturbance and steers against it.
    """

    dt_s: float = 0.05
    horizon: int = 20
    q_speed: float = 2.49
    q_sideslip: float = 548.0
    q_yaw_rate: float = 0.872
    q_steer: float = 122.5
    q_drive_kn: float = 0.276
    r_steer_step: float = 3.79
    r_drive_step_kn: float = 0.0047
    steer_limit_rad: float = 0.6
    drive_min_n: float = -6000.0
    drive_max_n: float = 8000.0
    steer_rate_radps: float = 9.7
    drive_rate_nps: float = 20000.0
    discretization: str = "zoh"
    disturbance_gain: float = 0.0294
    model_steer_lag_s: float = 0.027
    model_drive_lag_s: float = 0.05
    osqp_eps: float = 1e-5
    qp_solver: str = "daqp"
    path_states: bool = True
    q_lateral_error: float = 0.707
    q_course_error: float = 6.54
    terminal_cost: bool = True
    disturbance_start_gain: float = 0.175
    estimator_hold_s: float = 0.61
    estimator_uses_actuators: bool = True
    estimator_model: str = "linear"
    feedback_in_model: bool = True

    @classmethod
    def paper(cls) -> MpcConfig:
        """The paper's formulation with the weights that complete the nominal 8 (REFERENCE.md section 7)."""
        return cls(q_speed=1.0, q_sideslip=417.0, q_yaw_rate=26.0, q_steer=5.5, q_drive_kn=0.2,
                   r_steer_step=56.0, r_drive_step_kn=0.024, steer_rate_radps=3.0, discretization="euler",
                   model_steer_lag_s=0.0, model_drive_lag_s=0.0, path_states=False, q_lateral_error=0.0,
                   q_course_error=0.0, disturbance_gain=0.0, feedback_in_model=False, terminal_cost=False,
                   qp_solver="osqp")

    def __post_init__(self) -> None:
        ranges = {
            "dt_s": (0.005, 0.5), "horizon": (1, 100), "steer_limit_rad": (0.05, 1.2),
            "drive_min_n": (-30000.0, 0.0), "drive_max_n": (0.0, 30000.0), "steer_rate_radps": (0.05, 50.0),
            "drive_rate_nps": (100.0, 1e6), "disturbance_gain": (0.0, 1.0), "osqp_eps": (1e-10, 1e-2),
            "model_steer_lag_s": (0.0, 0.5), "model_drive_lag_s": (0.0, 1.0), "estimator_hold_s": (0.0, 10.0),
            "disturbance_start_gain": (0.0, 1.0),
        }
        if self.estimator_model not in ("linear", "nonlinear"):
            raise ConfigError(f"mpc.estimator_model must be 'linear' or 'nonlinear', got {self.estimator_model!r}")
        if self.qp_solver not in ("daqp", "osqp"):
            raise ConfigError(f"mpc.qp_solver must be 'daqp' or 'osqp', got {self.qp_solver!r}")
        if self.discretization not in ("euler", "zoh"):
            raise ConfigError(f"mpc.discretization must be 'euler' or 'zoh', got {self.discretization!r}")
        weights = {f.name: (0.0, 1e7) for f in fields(self) if f.name.startswith(("q_", "r_"))}
        check_ranges(self, "mpc", {**weights, **ranges})
        if not isinstance(self.terminal_cost, bool):
            raise ConfigError(f"mpc.terminal_cost must be true or false, got {self.terminal_cost!r}")
        for name in ("feedback_in_model", "estimator_uses_actuators"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"mpc.{name} must be true or false, got {getattr(self, name)!r}")
        if not isinstance(self.path_states, bool):
            raise ConfigError(f"mpc.path_states must be true or false, got {self.path_states!r}")
        if not isinstance(self.horizon, int):
            raise ConfigError(f"mpc.horizon must be an integer in [1, 100], got {self.horizon!r}")

    @property
    def models_actuator_lag(self) -> bool:
        return self.model_steer_lag_s > 0.0 or self.model_drive_lag_s > 0.0

    @property
    def state_weights(self) -> np.ndarray:
        """Q on the model states ([V, beta, r] or [V, beta, r, e, dpsi])."""
        path = [self.q_lateral_error, self.q_course_error] if self.path_states else []
        return np.array([self.q_speed, self.q_sideslip, self.q_yaw_rate, *path])

    @property
    def actuator_weights(self) -> np.ndarray:
        """Q on [delta, Fxr kN]."""
        return np.array([self.q_steer, self.q_drive_kn])

    @property
    def input_weights(self) -> np.ndarray:
        return np.array([self.r_steer_step, self.r_drive_step_kn])


def to_scaled(state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """z = [V, beta, r, delta, Fxr kN] from state [V, beta, r] and inputs [delta, Fxr N]."""
    return np.array([state[0], state[1], state[2], inputs[0], inputs[1] * KN])


def scale_inputs(inputs: np.ndarray) -> np.ndarray:
    """[delta, Fxr kN] from [delta, Fxr N]."""
    return np.array([inputs[0], inputs[1] * KN])


def _with_path_errors(a_c: np.ndarray, b_c: np.ndarray, equilibrium: Equilibrium) -> tuple[np.ndarray, np.ndarray]:
    """Adds the lateral error e and course error dpsi to the linearized model (not in the paper).

    With the conventions of :mod:`driftlab.core.track` (e > 0 right of the driving direction, dpsi = path
    heading - course), on a circle of radius R turned in direction s = sign(r_eq):
        e_dot = V sin(dpsi),   dpsi_dot = s V cos(dpsi) / (R + s e) - r - beta_dot,
    linearized at e = dpsi = 0 where s V / R = r_eq.
    """
    speed = equilibrium.speed_mps
    turn = math.copysign(1.0, equilibrium.yaw_rate_radps)
    radius = speed / abs(equilibrium.yaw_rate_radps)
    n = N_X + 2
    a_path = np.zeros((n, n))
    a_path[:N_X, :N_X] = a_c
    a_path[3, 4] = speed
    a_path[4, :N_X] = -a_c[1]
    a_path[4, 0] += turn / radius
    a_path[4, 2] -= 1.0
    a_path[4, 3] = -speed / radius**2
    b_path = np.zeros((n, N_U))
    b_path[:N_X] = b_c
    b_path[4] = -b_c[1]
    return a_path, b_path


def _with_actuator_lag(a_c: np.ndarray, b_c: np.ndarray, config: MpcConfig) -> tuple[np.ndarray, np.ndarray]:
    """Continuous model with first-order actuators: states [x, delta_a, Fxr_a], inputs the commands."""
    lags = np.array([max(config.model_steer_lag_s, 1e-4), max(config.model_drive_lag_s, 1e-4)])
    n_x = a_c.shape[0]
    a_sys = np.zeros((n_x + N_U, n_x + N_U))
    a_sys[:n_x, :n_x] = a_c
    a_sys[:n_x, n_x:] = b_c
    a_sys[n_x:, n_x:] = np.diag(-1.0 / lags)
    b_sys = np.zeros((n_x + N_U, N_U))
    b_sys[n_x:, :] = np.diag(1.0 / lags)
    return a_sys, b_sys


def _with_steer_feedback(a_sys: np.ndarray, b_sys: np.ndarray, gain_radpm: float, lookahead_m: float) -> np.ndarray:
    """Closes the paper's steering feedback delta_f = delta_mpc + k (e + x_la dpsi) (eq. 11, sin linearized)
    inside the model: the steering command becomes the MPC's input plus k [0 0 0 1 x_la 0 ...] x."""
    row = np.zeros(a_sys.shape[0])
    row[N_X] = gain_radpm
    row[N_X + 1] = gain_radpm * lookahead_m
    return a_sys + np.outer(b_sys[:, 0], row)


def _terminal_weight(a_mat: np.ndarray, b_mat: np.ndarray, q_mat: np.ndarray, r_mat: np.ndarray) -> np.ndarray:
    """The infinite-horizon cost-to-go P of the unconstrained problem (discrete Riccati equation): as the last
    stage's weight it makes the finite-horizon MPC equal the LQR where no limit is active, which stabilizes
    the drift's saddle (an MPC without it on a 1 s horizon need not)."""
    try:
        p_mat = scipy.linalg.solve_discrete_are(a_mat, b_mat, q_mat + 1e-9 * np.eye(len(q_mat)), r_mat)
    except (np.linalg.LinAlgError, ValueError):
        return q_mat
    return 0.5 * (p_mat + p_mat.T)


def discretize(a_mat: np.ndarray, b_mat: np.ndarray, dt_s: float, method: str):
    """Discrete (Ad, Bd, Gd) for x+ = Ad x + Bd u + Gd d, with d an additive disturbance on xdot."""
    n, m = b_mat.shape
    if method == "euler":
        return np.eye(n) + dt_s * a_mat, dt_s * b_mat, dt_s * np.eye(n)
    block = np.zeros((2 * n + m, 2 * n + m))
    block[:n, :n] = a_mat
    block[:n, n:n + m] = b_mat
    block[:n, n + m:] = np.eye(n)
    phi = scipy.linalg.expm(block * dt_s)
    return phi[:n, :n], phi[:n, n:n + m], phi[:n, n + m:]


@dataclass
class MpcSolution:
    """One step's result."""

    steer_rad: float
    drive_force_n: float
    used_osqp: bool
    ok: bool
    increments: np.ndarray  # the whole optimal increment sequence, [d_delta, d_Fxr kN] per step


class QpArrays(NamedTuple):
    """A :class:`ReferenceQp`'s constants as the compiled closed loop reads them (numba takes a named tuple)."""

    a_cont: np.ndarray  # continuous Jacobians at the equilibrium, A (3x3) and B (3x2, per kN)
    b_cont: np.ndarray
    x_eq: np.ndarray  # [V, beta, r]
    u_eq_scaled: np.ndarray  # [delta, Fxr kN]
    z_eq: np.ndarray  # [V, beta, r, delta, Fxr kN]
    speed_mps: float
    yaw_rate_radps: float
    z_lin: np.ndarray  # the linearization point in the QP's state layout
    gain_state: np.ndarray
    gain_disturbance: np.ndarray
    gain_reference: np.ndarray
    gamma_t_q: np.ndarray
    phi: np.ndarray
    lam: np.ndarray
    repeat: np.ndarray
    cumsum: np.ndarray
    step_limit: np.ndarray
    input_lo: np.ndarray
    input_hi: np.ndarray
    path_states: bool
    models_lag: bool
    horizon: int
    steer_limit_rad: float
    drive_min_kn: float
    drive_max_kn: float


@njit(cache=True)
def clip(x, lo, hi):
    """np.clip of a scalar, to the bit (NaN passes through; max first, then min)."""
    if x != x:
        return x
    x = x if x > lo else lo
    return x if x < hi else hi


@njit(cache=True)
def pack_state(path_states, models_lag, state, path_errors, actuators_scaled, previous_commands_scaled):
    """z = [V, beta, r, (e, dpsi,) (delta_a, Fxr_a kN,) delta_prev, Fxr_prev kN]: the QP's state, with the
    path errors if ``path_states`` and the actuator states if ``models_lag``."""
    n = 3 + (2 if path_states else 0) + (N_U if models_lag else 0) + N_U
    z = np.empty(n)
    z[:3] = state
    i = 3
    if path_states:
        z[i:i + 2] = path_errors
        i += 2
    if models_lag:
        z[i:i + N_U] = actuators_scaled
        i += N_U
    z[i:i + N_U] = previous_commands_scaled
    return z


@njit(cache=True)
def reference_terms(qa, z_ref):
    """The reference's share of the unconstrained minimizer and of the QP's linear term."""
    aug = pack_state(qa.path_states, qa.models_lag, z_ref[:N_X], np.zeros(2), z_ref[N_X:], z_ref[N_X:]) - qa.z_lin
    n_z = aug.shape[0]
    deviation = np.empty(qa.horizon * n_z)
    for k in range(qa.horizon):
        deviation[k * n_z:(k + 1) * n_z] = aug
    return np.dot(qa.gain_reference, deviation), np.dot(qa.gamma_t_q, deviation)


@njit(cache=True)
def unconstrained_increments(qa, z_now, ref_gain_term, disturbance):
    """(du, dz, offset, within): the unconstrained minimizer, the state's deviation from the linearization
    point, the previous command repeated over the horizon, and whether du satisfies every limit (then it *is*
    the QP's solution: the QP is strictly convex and no constraint is active)."""
    dz = z_now - qa.z_lin
    du = ref_gain_term - np.dot(qa.gain_state, dz) - np.dot(qa.gain_disturbance, disturbance)
    u_prev = z_now[-N_U:].copy()
    offset = np.dot(qa.repeat, u_prev)
    cumulative = offset + np.dot(qa.cumsum, du)
    tol = 1e-9
    within = ((np.abs(du) - qa.step_limit).max() <= tol and (qa.input_lo - cumulative).max() <= tol
              and (cumulative - qa.input_hi).max() <= tol)
    return du, dz, offset, within


@njit(cache=True)
def constrained_terms(qa, dz, disturbance, ref_linear_term, offset):
    """OSQP's (q, l, u) for this step: the condensed QP's linear term and the limits on [du, cumulative u]."""
    q = np.dot(qa.gamma_t_q, np.dot(qa.phi, dz) + np.dot(qa.lam, disturbance)) - ref_linear_term
    lower = np.concatenate((-qa.step_limit, qa.input_lo - offset))
    upper = np.concatenate((qa.step_limit, qa.input_hi - offset))
    return q, lower, upper


@njit(cache=True)
def next_commands(qa, u_prev, du):
    """(steer rad, drive kN): the first increment applied to the previous commands, within the limits."""
    return (clip(u_prev[0] + du[0], -qa.steer_limit_rad, qa.steer_limit_rad),
            clip(u_prev[1] + du[1], qa.drive_min_kn, qa.drive_max_kn))


@njit(cache=True)
def update_estimate(estimate, n_updates, innovation, gain, start_gain, dt_s, limit):
    """Offset-free MPC's disturbance estimate d on (Vdot, betadot, rdot), a first-order filter; ``estimate`` and
    the count ``n_updates[0]`` change in place (a frozen estimate is simply not updated).

    The measurement d_meas = innovation / dt = (x_meas - x_pred) / dt, x_pred being the controller model's
    one-step prediction without disturbance; d follows it through d += g (d_meas - d), clipped to ``limit``. The
    gain starts as a running mean capped at ``start_gain``, g = max(gain, min(start_gain, 1 / n)) over the first
    n measurements: the episode starts at the *model's* drift, so the mismatch matters most then, and a plain
    small gain leaves the car metres off its circle; an uncapped running mean takes the first, transient,
    measurements at full weight and throws the car out of the drift.
    """
    if gain > 0.0:
        n_updates[0] += 1
        step_gain = max(gain, min(start_gain, 1.0 / n_updates[0]))
        measured = innovation / dt_s
        value = estimate + step_gain * (measured - estimate)
        for i in range(N_X):
            estimate[i] = clip(value[i], -limit[i], limit[i])
    return estimate


class ReferenceQp:
    """The condensed QP for one reference equilibrium (built once, reused every step)."""

    def __init__(self, config: MpcConfig, equilibrium: Equilibrium, p_model: np.ndarray,
                 feedback_gain_radpm: float = 0.0, lookahead_m: float = 0.0) -> None:
        self.config = config
        self.equilibrium = equilibrium
        a_c, b_c = jacobians(equilibrium.state, equilibrium.inputs, p_model)
        b_c = b_c.copy()
        b_c[:, 1] /= KN  # per kN
        self.a_cont, self.b_cont = a_c, b_c
        self.models_lag = config.models_actuator_lag
        self.path_states = config.path_states
        a_sys, b_sys = _with_path_errors(a_c, b_c, equilibrium) if self.path_states else (a_c, b_c)
        a_sys, b_sys = _with_actuator_lag(a_sys, b_sys, config) if self.models_lag else (a_sys, b_sys)
        if config.feedback_in_model and self.path_states:
            a_sys = _with_steer_feedback(a_sys, b_sys, feedback_gain_radpm, lookahead_m)
        n_sys = a_sys.shape[0]  # model states (3 or 5) plus 2 actuator states [delta_a, Fxr_a kN] if modelled
        ad, bd, gd = discretize(a_sys, b_sys, config.dt_s, config.discretization)
        # The disturbance acts on (Vdot, betadot, rdot); the course error's rate holds -betadot, so a sideslip
        # disturbance moves it too (without this the MPC, believing the course drifts, held the car metres
        # off its circle in a steady drift).
        entry = np.zeros((gd.shape[0], N_X))
        entry[:N_X, :N_X] = np.eye(N_X)
        if self.path_states:
            entry[N_X + 1, 1] = -1.0
        gd = gd @ entry
        self.ad, self.bd, self.gd = ad, bd, gd
        self.n_z = n_z = n_sys + N_U
        self.z_lin = self.augmented_reference(to_scaled(equilibrium.state, equilibrium.inputs))
        n_h = config.horizon
        aa = np.zeros((n_z, n_z))
        aa[:n_sys, :n_sys] = ad
        aa[:n_sys, n_sys:] = bd
        aa[n_sys:, n_sys:] = np.eye(N_U)
        ba = np.vstack([bd, np.eye(N_U)])
        ga = np.vstack([gd, np.zeros((N_U, N_X))])
        phi = np.zeros((n_h * n_z, n_z))
        gamma = np.zeros((n_h * n_z, n_h * N_U))
        lam = np.zeros((n_h * n_z, N_X))
        power = np.eye(n_z)
        lam_acc = np.zeros((n_z, N_X))
        a_pow_b = [ba]
        for _ in range(1, n_h):
            a_pow_b.append(aa @ a_pow_b[-1])
        for k in range(n_h):
            lam_acc = aa @ lam_acc + ga
            power = aa @ power
            phi[k * n_z:(k + 1) * n_z] = power
            lam[k * n_z:(k + 1) * n_z] = lam_acc
            for j in range(k + 1):
                gamma[k * n_z:(k + 1) * n_z, j * N_U:(j + 1) * N_U] = a_pow_b[k - j]
        # Q weighs [delta, Fxr] on the actuator states when modelled, else on the held commands.
        lag_part = [config.actuator_weights, np.zeros(N_U)] if self.models_lag else [config.actuator_weights]
        weights = np.concatenate([config.state_weights, *lag_part])
        q_bar = np.kron(np.eye(n_h), np.diag(weights))
        r_bar = np.kron(np.eye(n_h), np.diag(config.input_weights))
        if config.terminal_cost:
            q_bar[-n_z:, -n_z:] = _terminal_weight(aa, ba, np.diag(weights), np.diag(config.input_weights))
        hessian = gamma.T @ q_bar @ gamma + r_bar
        hessian = 0.5 * (hessian + hessian.T)
        self.hessian = hessian
        self.gamma_t_q = gamma.T @ q_bar
        self.phi = phi
        self.lam = lam
        chol = scipy.linalg.cho_factor(hessian)
        gain = scipy.linalg.cho_solve(chol, self.gamma_t_q)  # H^-1 Gamma' Qbar
        self.gain_state = gain @ phi
        self.gain_disturbance = gain @ lam
        self.gain_reference = gain
        # Constraints on the increments: bounds on each du and on u_{-1} + cumulative sums.
        cumsum = np.kron(np.tril(np.ones((n_h, n_h))), np.eye(N_U))
        self.cumsum = cumsum
        self.repeat = np.kron(np.ones((n_h, 1)), np.eye(N_U))  # u -> [u, u, ..., u]
        self.constraint_matrix = np.vstack([np.eye(n_h * N_U), cumsum])
        self.daqp_sense = np.zeros(2 * n_h * N_U, dtype=np.intc)  # all inequalities
        step_limit = np.array([config.steer_rate_radps * config.dt_s, config.drive_rate_nps * config.dt_s * KN])
        self.step_limit = np.tile(step_limit, n_h)
        self.input_lo = np.tile(np.array([-config.steer_limit_rad, config.drive_min_n * KN]), n_h)
        self.input_hi = np.tile(np.array([config.steer_limit_rad, config.drive_max_n * KN]), n_h)
        self.arrays = QpArrays(
            a_cont=np.ascontiguousarray(self.a_cont), b_cont=np.ascontiguousarray(self.b_cont),
            x_eq=equilibrium.state, u_eq_scaled=scale_inputs(equilibrium.inputs),
            z_eq=to_scaled(equilibrium.state, equilibrium.inputs), speed_mps=float(equilibrium.speed_mps),
            yaw_rate_radps=float(equilibrium.yaw_rate_radps), z_lin=self.z_lin, gain_state=self.gain_state,
            gain_disturbance=self.gain_disturbance, gain_reference=self.gain_reference, gamma_t_q=self.gamma_t_q,
            phi=self.phi, lam=self.lam, repeat=self.repeat, cumsum=self.cumsum, step_limit=self.step_limit,
            input_lo=self.input_lo, input_hi=self.input_hi, path_states=bool(self.path_states),
            models_lag=bool(self.models_lag), horizon=int(n_h), steer_limit_rad=float(config.steer_limit_rad),
            drive_min_kn=float(config.drive_min_n * KN), drive_max_kn=float(config.drive_max_n * KN))

    def augmented_reference(self, z_ref: np.ndarray) -> np.ndarray:
        """The 5-entry reference [V, beta, r, delta, Fxr kN] in this QP's state layout (path errors 0)."""
        return self.pack_state(z_ref[:N_X], np.zeros(2), z_ref[N_X:], z_ref[N_X:])

    def pack_state(self, state: np.ndarray, path_errors: np.ndarray, actuators_scaled: np.ndarray,
                   previous_commands_scaled: np.ndarray) -> np.ndarray:
        """z = [V, beta, r, (e, dpsi,) (delta_a, Fxr_a kN,) delta_prev, Fxr_prev kN] for this QP."""
        return pack_state(bool(self.path_states), bool(self.models_lag), np.asarray(state, float),
                          np.asarray(path_errors, float), np.asarray(actuators_scaled, float),
                          np.asarray(previous_commands_scaled, float))

    def session(self) -> QpSession:
        """A fresh solver for one episode (its OSQP warm start and caches die with the episode)."""
        return QpSession(self)


class QpSession:
    """One episode's use of a :class:`ReferenceQp`: the OSQP instance, set up on first need.

    Kept apart from the cached :class:`ReferenceQp` so that no solver state (OSQP's warm start, its adapted
    rho) survives from one episode to the next: an episode is a pure function of its inputs.
    """

    def __init__(self, qp: ReferenceQp) -> None:
        self.qp = qp
        self._solver = None

    def _osqp(self):
        if self._solver is None:
            import osqp  # only the osqp solver needs it (~0.2 s of a cold start)
            import scipy.sparse as sp

            qp = self.qp
            solver = osqp.OSQP()
            solver.setup(
                sp.csc_matrix(np.triu(qp.hessian)), np.zeros(qp.hessian.shape[0]),
                sp.csc_matrix(qp.constraint_matrix),
                np.concatenate([-qp.step_limit, qp.input_lo]), np.concatenate([qp.step_limit, qp.input_hi]),
                eps_abs=qp.config.osqp_eps, eps_rel=qp.config.osqp_eps, polishing=False, verbose=False,
                warm_starting=True, max_iter=4000,
            )
            self._solver = solver
        return self._solver

    def solve_constrained(self, q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, bool]:
        """The condensed QP with this step's terms (:func:`constrained_terms`): (du, ok); du is zero when the
        solver failed."""
        if self.qp.config.qp_solver == "daqp":
            x, ok = self._daqp(q, lower, upper)
        else:
            solver = self._osqp()
            solver.update(q=q, l=lower, u=upper)
            result = solver.solve(raise_error=False)
            x, ok = result.x, result.info.status_val in (1, 2) and result.x is not None
        ok = ok and bool(np.all(np.isfinite(x)))
        step_limit = self.qp.step_limit
        return (np.clip(x, -step_limit, step_limit) if ok else np.zeros(len(step_limit))), ok

    def _daqp(self, q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, bool]:
        """DAQP: the first 2 Nc limits are bounds on du, the rest rows of the cumulative-sum matrix."""
        qp = self.qp
        x, _, exitflag, _ = daqp.solve(qp.hessian, q, qp.cumsum, upper, lower, qp.daqp_sense)
        return np.asarray(x), exitflag > 0

    def solve(self, z_now: np.ndarray, z_ref: np.ndarray, disturbance: np.ndarray) -> MpcSolution:
        """Optimal increments (the closed loop does the same with the compiled parts directly).

        Args:
            z_now: the QP's state (:meth:`ReferenceQp.pack_state`), the last two entries being the previous commands.
            z_ref: reference [V, beta, r, delta, Fxr kN].
            disturbance: estimated additive disturbance on (Vdot, betadot, rdot).
        """
        qa = self.qp.arrays
        z_now, z_ref, disturbance = (np.asarray(v, float) for v in (z_now, z_ref, disturbance))
        ref_gain_term, ref_linear_term = reference_terms(qa, z_ref)
        du, dz, offset, within = unconstrained_increments(qa, z_now, ref_gain_term, disturbance)
        ok = True
        if not within:
            du, ok = self.solve_constrained(*constrained_terms(qa, dz, disturbance, ref_linear_term, offset))
        steer, drive_kn = next_commands(qa, z_now[-N_U:].copy(), du)
        return MpcSolution(steer, drive_kn / KN, not within, ok, du)
