"""CommonRoad's single-track drift model (STD), compiled: ``vehiclemodels.vehicle_dynamics_std`` (2020a, package
3.0.2) and its PAC2002 tyre functions, statement for statement, on the packed parameters of
:mod:`driftlab.core.commonroad.parameters`. ``tests/core/test_commonroad.py`` checks it against the package on
random states; the package stays the reference.

State (the package's layout): x, y [m], steering angle delta [rad], speed V [m/s], yaw psi [rad], yaw rate r
[rad/s], sideslip beta [rad], front and rear wheel speeds [rad/s]. Inputs: steering velocity [rad/s] and
longitudinal acceleration [m/s^2] (turned into rear drive torque m R_w u2 for the rear-wheel-drive cars).
Sign convention as DriftLab's: y to the left, r > 0 turning left, a left-hand drift has beta < 0.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from driftlab.core.commonroad.parameters import (
    CR_ACCEL_MAX,
    CR_BRAKE_SPLIT,
    CR_CG_HEIGHT,
    CR_CG_TO_FRONT,
    CR_CG_TO_REAR,
    CR_DRIVE_SPLIT,
    CR_MASS,
    CR_SPEED_MAX,
    CR_SPEED_MIN,
    CR_SPEED_SWITCH,
    CR_STEER_MAX,
    CR_STEER_MIN,
    CR_STEER_RATE_MAX,
    CR_STEER_RATE_MIN,
    CR_WHEEL_INERTIA,
    CR_WHEEL_RADIUS,
    CR_YAW_INERTIA,
    T,
)

# State layout of the package.
S_X, S_Y, S_STEER, S_SPEED, S_YAW, S_YAW_RATE, S_SIDESLIP, S_OMEGA_F, S_OMEGA_R = range(9)
N_STD = 9
GRAVITY_MPS2 = 9.81  # the package's constant

# PAC2002 coefficients by packed index (numba reads module-level integers as constants).
P_CX1, P_DX1, P_DX3, P_EX1, P_KX1, P_HX1, P_VX1 = (T[k] for k in ("p_cx1", "p_dx1", "p_dx3", "p_ex1", "p_kx1",
                                                                   "p_hx1", "p_vx1"))
R_BX1, R_BX2, R_CX1, R_EX1, R_HX1 = (T[k] for k in ("r_bx1", "r_bx2", "r_cx1", "r_ex1", "r_hx1"))
P_CY1, P_DY1, P_DY3, P_EY1, P_KY1, P_HY1, P_HY3, P_VY1, P_VY3 = (
    T[k] for k in ("p_cy1", "p_dy1", "p_dy3", "p_ey1", "p_ky1", "p_hy1", "p_hy3", "p_vy1", "p_vy3"))
R_BY1, R_BY2, R_BY3, R_CY1, R_EY1, R_HY1, R_VY1, R_VY3, R_VY4, R_VY5, R_VY6 = (
    T[k] for k in ("r_by1", "r_by2", "r_by3", "r_cy1", "r_ey1", "r_hy1", "r_vy1", "r_vy3", "r_vy4", "r_vy5",
                   "r_vy6"))


@njit(cache=True)
def _sign(x):
    if x > 0:
        return 1.0
    if x < 0:
        return -1.0
    return 0.0


@njit(cache=True)
def formula_longitudinal(kappa, gamma, f_z, p):
    """PAC2002 pure longitudinal force [N] (the package's sign: kappa negated)."""
    kappa = -kappa
    s_hx = p[P_HX1]
    s_vx = f_z * p[P_VX1]
    kappa_x = kappa + s_hx
    mu_x = p[P_DX1] * (1 - p[P_DX3] * gamma ** 2)
    c_x = p[P_CX1]
    d_x = mu_x * f_z
    e_x = p[P_EX1]
    k_x = f_z * p[P_KX1]
    b_x = k_x / (c_x * d_x)
    return d_x * math.sin(c_x * math.atan(b_x * kappa_x - e_x * (b_x * kappa_x - math.atan(b_x * kappa_x))) + s_vx)


@njit(cache=True)
def formula_lateral(alpha, gamma, f_z, p):
    """PAC2002 pure lateral force [N] and its friction coefficient mu_y."""
    s_hy = _sign(gamma) * (p[P_HY1] + p[P_HY3] * math.fabs(gamma))
    s_vy = _sign(gamma) * f_z * (p[P_VY1] + p[P_VY3] * math.fabs(gamma))
    alpha_y = alpha + s_hy
    mu_y = p[P_DY1] * (1 - p[P_DY3] * gamma ** 2)
    c_y = p[P_CY1]
    d_y = mu_y * f_z
    e_y = p[P_EY1]
    k_y = f_z * p[P_KY1]
    b_y = k_y / (c_y * d_y)
    f_y = d_y * math.sin(c_y * math.atan(b_y * alpha_y - e_y * (b_y * alpha_y - math.atan(b_y * alpha_y)))) + s_vy
    return f_y, mu_y


@njit(cache=True)
def formula_longitudinal_comb(kappa, alpha, f0_x, p):
    s_hxalpha = p[R_HX1]
    alpha_s = alpha + s_hxalpha
    b_xalpha = p[R_BX1] * math.cos(math.atan(p[R_BX2] * kappa))
    c_xalpha = p[R_CX1]
    e_xalpha = p[R_EX1]
    d_xalpha = f0_x / (math.cos(c_xalpha * math.atan(
        b_xalpha * s_hxalpha - e_xalpha * (b_xalpha * s_hxalpha - math.atan(b_xalpha * s_hxalpha)))))
    return d_xalpha * math.cos(
        c_xalpha * math.atan(b_xalpha * alpha_s - e_xalpha * (b_xalpha * alpha_s - math.atan(b_xalpha * alpha_s))))


@njit(cache=True)
def formula_lateral_comb(kappa, alpha, gamma, mu_y, f_z, f0_y, p):
    s_hykappa = p[R_HY1]
    kappa_s = kappa + s_hykappa
    b_ykappa = p[R_BY1] * math.cos(math.atan(p[R_BY2] * (alpha - p[R_BY3])))
    c_ykappa = p[R_CY1]
    e_ykappa = p[R_EY1]
    d_ykappa = f0_y / (math.cos(c_ykappa * math.atan(
        b_ykappa * s_hykappa - e_ykappa * (b_ykappa * s_hykappa - math.atan(b_ykappa * s_hykappa)))))
    d_vykappa = mu_y * f_z * (p[R_VY1] + p[R_VY3] * gamma) * math.cos(math.atan(p[R_VY4] * alpha))
    s_vykappa = d_vykappa * math.sin(p[R_VY5] * math.atan(p[R_VY6] * kappa))
    return d_ykappa * math.cos(c_ykappa * math.atan(
        b_ykappa * kappa_s - e_ykappa * (b_ykappa * kappa_s - math.atan(b_ykappa * kappa_s)))) + s_vykappa


@njit(cache=True)
def steering_constraints(steering_angle, steering_velocity, p):
    if ((steering_angle <= p[CR_STEER_MIN] and steering_velocity <= 0)
            or (steering_angle >= p[CR_STEER_MAX] and steering_velocity >= 0)):
        return 0.0
    if steering_velocity <= p[CR_STEER_RATE_MIN]:
        return p[CR_STEER_RATE_MIN]
    if steering_velocity >= p[CR_STEER_RATE_MAX]:
        return p[CR_STEER_RATE_MAX]
    return steering_velocity


@njit(cache=True)
def acceleration_constraints(velocity, acceleration, p):
    """The package's acceleration limits, the power cap a_max v_switch / V above v_switch included."""
    if velocity > p[CR_SPEED_SWITCH]:
        pos_limit = p[CR_ACCEL_MAX] * p[CR_SPEED_SWITCH] / velocity
    else:
        pos_limit = p[CR_ACCEL_MAX]
    if (velocity <= p[CR_SPEED_MIN] and acceleration <= 0) or (velocity >= p[CR_SPEED_MAX] and acceleration >= 0):
        return 0.0
    if acceleration <= -p[CR_ACCEL_MAX]:
        return -p[CR_ACCEL_MAX]
    if acceleration >= pos_limit:
        return pos_limit
    return acceleration


@njit(cache=True)
def rear_tyre_state(x, accel, p):
    """(longitudinal slip s_r, rear longitudinal force F_xr [N]) at state ``x`` under the constrained
    acceleration input ``accel`` (the package's load transfer reads the commanded acceleration)."""
    lf, lr, m = p[CR_CG_TO_FRONT], p[CR_CG_TO_REAR], p[CR_MASS]
    v_min = 0.1
    alpha_r = math.atan((x[S_SPEED] * math.sin(x[S_SIDESLIP]) - x[S_YAW_RATE] * lr)
                        / (x[S_SPEED] * math.cos(x[S_SIDESLIP]))) if x[S_SPEED] > v_min else 0.0
    f_zr = m * (accel * p[CR_CG_HEIGHT] + GRAVITY_MPS2 * lf) / (lr + lf)
    u_wr = max(0.0, x[S_SPEED] * math.cos(x[S_SIDESLIP]))
    s_r = 1 - p[CR_WHEEL_RADIUS] * x[S_OMEGA_R] / max(u_wr, v_min)
    f0_xr = formula_longitudinal(s_r, 0.0, f_zr, p)
    return s_r, formula_longitudinal_comb(s_r, alpha_r, f0_xr, p)


@njit(cache=True)
def std_derivatives(x, u_init, p):
    """d/dt of the STD state under inputs [steering velocity, longitudinal acceleration] (the package's
    ``vehicle_dynamics_std``; it also clamps the wheel speeds of its argument at 0, which the caller does here)."""
    lf = p[CR_CG_TO_FRONT]
    lr = p[CR_CG_TO_REAR]
    lwb = lf + lr
    m = p[CR_MASS]
    inertia = p[CR_YAW_INERTIA]
    v_s = 0.2
    v_b = 0.05
    v_min = v_s / 2
    u0 = steering_constraints(x[S_STEER], u_init[0], p)
    u1 = acceleration_constraints(x[S_SPEED], u_init[1], p)

    if x[S_SPEED] > v_min:
        alpha_f = math.atan((x[3] * math.sin(x[6]) + x[5] * lf) / (x[3] * math.cos(x[6]))) - x[2]
        alpha_r = math.atan((x[3] * math.sin(x[6]) - x[5] * lr) / (x[3] * math.cos(x[6])))
    else:
        alpha_f = 0.0
        alpha_r = 0.0

    f_zf = m * (-u1 * p[CR_CG_HEIGHT] + GRAVITY_MPS2 * lr) / (lr + lf)
    f_zr = m * (u1 * p[CR_CG_HEIGHT] + GRAVITY_MPS2 * lf) / (lr + lf)

    u_wf = max(0.0, x[3] * math.cos(x[6]) * math.cos(x[2]) + (x[3] * math.sin(x[6]) + lf * x[5]) * math.sin(x[2]))
    u_wr = max(0.0, x[3] * math.cos(x[6]))

    s_f = 1 - p[CR_WHEEL_RADIUS] * x[7] / max(u_wf, v_min)
    s_r = 1 - p[CR_WHEEL_RADIUS] * x[8] / max(u_wr, v_min)

    f0_xf = formula_longitudinal(s_f, 0.0, f_zf, p)
    f0_xr = formula_longitudinal(s_r, 0.0, f_zr, p)
    f0_yf, mu_yf = formula_lateral(alpha_f, 0.0, f_zf, p)
    f0_yr, mu_yr = formula_lateral(alpha_r, 0.0, f_zr, p)
    f_xf = formula_longitudinal_comb(s_f, alpha_f, f0_xf, p)
    f_xr = formula_longitudinal_comb(s_r, alpha_r, f0_xr, p)
    f_yf = formula_lateral_comb(s_f, alpha_f, 0.0, mu_yf, f_zf, f0_yf, p)
    f_yr = formula_lateral_comb(s_r, alpha_r, 0.0, mu_yr, f_zr, f0_yr, p)

    if u1 > 0:
        t_b = 0.0
        t_e = m * p[CR_WHEEL_RADIUS] * u1
    else:
        t_b = m * p[CR_WHEEL_RADIUS] * u1
        t_e = 0.0

    d_v = 1 / m * (-f_yf * math.sin(x[2] - x[6]) + f_yr * math.sin(x[6]) + f_xr * math.cos(x[6])
                   + f_xf * math.cos(x[2] - x[6]))
    dd_psi = 1 / inertia * (f_yf * math.cos(x[2]) * lf - f_yr * lr + f_xf * math.sin(x[2]) * lf)
    if x[S_SPEED] > v_min:
        d_beta = -x[5] + 1 / (m * x[3]) * (f_yf * math.cos(x[2] - x[6]) + f_yr * math.cos(x[6])
                                           - f_xr * math.sin(x[6]) + f_xf * math.sin(x[2] - x[6]))
    else:
        d_beta = 0.0

    iw = p[CR_WHEEL_INERTIA]
    d_omega_f = 1 / iw * (-p[CR_WHEEL_RADIUS] * f_xf + p[CR_BRAKE_SPLIT] * t_b + p[CR_DRIVE_SPLIT] * t_e) \
        if x[7] >= 0 else 0.0
    d_omega_r = 1 / iw * (-p[CR_WHEEL_RADIUS] * f_xr + (1 - p[CR_BRAKE_SPLIT]) * t_b
                          + (1 - p[CR_DRIVE_SPLIT]) * t_e) if x[8] >= 0 else 0.0

    # The package blends in its kinematic model below ~0.2 m/s (numerically exactly 0 weight at drift speeds).
    beta_ks = math.atan(math.tan(x[2]) * lr / lwb)
    f_ks_v = u1
    f_ks_psi = x[3] * math.cos(beta_ks) * math.tan(x[2]) / lwb
    d_beta_ks = (lr * u0) / (lwb * math.cos(x[2]) ** 2 * (1 + (math.tan(x[2]) ** 2 * lr / lwb) ** 2))
    dd_psi_ks = 1 / lwb * (u1 * math.cos(x[6]) * math.tan(x[2]) - x[3] * math.sin(x[6]) * d_beta_ks * math.tan(x[2])
                           + x[3] * math.cos(x[6]) * u0 / math.cos(x[2]) ** 2)
    d_omega_f_ks = (1 / 0.02) * (u_wf / p[CR_WHEEL_RADIUS] - max(0.0, x[7]))
    d_omega_r_ks = (1 / 0.02) * (u_wr / p[CR_WHEEL_RADIUS] - max(0.0, x[8]))
    w_std = 0.5 * (math.tanh((x[3] - v_s) / v_b) + 1)
    w_ks = 1 - w_std

    f = np.empty(N_STD)
    f[0] = x[3] * math.cos(x[6] + x[4])
    f[1] = x[3] * math.sin(x[6] + x[4])
    f[2] = u0
    f[3] = w_std * d_v + w_ks * f_ks_v
    f[4] = w_std * x[5] + w_ks * f_ks_psi
    f[5] = w_std * dd_psi + w_ks * dd_psi_ks
    f[6] = w_std * d_beta + w_ks * d_beta_ks
    f[7] = w_std * d_omega_f + w_ks * d_omega_f_ks
    f[8] = w_std * d_omega_r + w_ks * d_omega_r_ks
    return f
