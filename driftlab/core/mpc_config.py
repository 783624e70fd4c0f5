"""The MPC's settings (weights, horizon, limits, solver) and the QP's units and sizes."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from driftlab.core.errors import ConfigError
from driftlab.core.validation import check_ranges

KN = 1e-3  # the QP's drive-force unit is kN
N_PER_KN = 1e3  # its inverse, exactly (1 / KN is not)
N_X = 3
N_U = 2
N_Z = N_X + N_U
STEER_LIMIT_RANGE_RAD = (0.05, 1.2)  # what ``steer_limit_rad`` may be set to


@dataclass(frozen=True)
class MpcConfig:
    """Controller settings. The defaults are DriftLab's formulation; :meth:`paper` is the paper's.

    Default ("extended"): the paper's linear MPC plus what the mismatched default plant needs: lateral and
    course errors as model states (path_states), first-order actuator lags in the model, exact (ZOH)
    discretization, and weights from a random search on the default plant (benchmarks/tune_weights.py; the
    defaults are its best set, rounded).
    Paper: 3-state model linearized at the target, Euler, the weights of docs/reference.md (The paper's controller).

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
        """The paper's formulation with the weights that complete the nominal 8 (docs/reference.md, The paper's
        controller)."""
        return cls(q_speed=1.0, q_sideslip=417.0, q_yaw_rate=26.0, q_steer=5.5, q_drive_kn=0.2,
                   r_steer_step=56.0, r_drive_step_kn=0.024, steer_rate_radps=3.0, discretization="euler",
                   model_steer_lag_s=0.0, model_drive_lag_s=0.0, path_states=False, q_lateral_error=0.0,
                   q_course_error=0.0, disturbance_gain=0.0, feedback_in_model=False, terminal_cost=False,
                   qp_solver="osqp")

    def __post_init__(self) -> None:
        ranges = {
            "dt_s": (0.005, 0.5), "horizon": (1, 100), "steer_limit_rad": STEER_LIMIT_RANGE_RAD,
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
