"""CommonRoad's multi-body model (MB, 29 states: sprung mass with roll and pitch, two unsprung axles, four wheel
speeds, PAC2002 tyres with camber), compiled: ``vehiclemodels.vehicle_dynamics_mb`` (2020a, package 3.0.2)
statement for statement on packed parameters; ``tests/core/test_commonroad.py`` checks it against the package.

State (the package's layout): x, y, delta, vx, psi, r, roll, roll rate, pitch, pitch rate, vy, z, vz, front
unsprung roll, its rate, vy, z, vz, the same for the rear, the four wheel speeds (lf, rf, lr, rr) and the two
axles' lateral compliance (delta_y_f, delta_y_r). Its fastest mode is a wheel's speed (its slip stiffness over
its inertia and forward speed: ~ -350 1/s in the 0.5 rad drift, ~1/V below it), which sets RK4's substep.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

from driftlab.core.commonroad.parameters import CR_TYRE, TYRE_KEYS, ParameterSet, package_parameters
from driftlab.core.commonroad.std import (
    formula_lateral,
    formula_lateral_comb,
    formula_longitudinal,
    formula_longitudinal_comb,
)

N_MB = 29
MB_KEYS = ("D_f", "D_r", "E_f", "E_r", "I_Phi_s", "I_uf", "I_ur", "I_xz_s", "I_y_s", "I_y_w", "I_z", "K_lt", "K_rad",
           "K_ras", "K_sdf", "K_sdr", "K_sf", "K_sr", "K_tsf", "K_tsr", "K_zt", "R_w", "T_f", "T_r", "T_sb", "T_se",
           "a", "b", "h_raf", "h_rar", "h_s", "m", "m_s", "m_uf", "m_ur")
(D_F, D_R, E_F, E_R, I_PHI_S, I_UF, I_UR, I_XZ_S, I_Y_S, I_Y_W, I_Z, K_LT, K_RAD, K_RAS, K_SDF, K_SDR, K_SF, K_SR,
 K_TSF, K_TSR, K_ZT, R_W, T_F, T_R, T_SB, T_SE, A, B, H_RAF, H_RAR, H_S, M, M_S, M_UF, M_UR) = range(len(MB_KEYS))
(MB_STEER_MIN, MB_STEER_MAX, MB_STEER_RATE_MIN, MB_STEER_RATE_MAX, MB_SPEED_MIN, MB_SPEED_MAX, MB_SPEED_SWITCH,
 MB_ACCEL_MAX) = range(len(MB_KEYS), len(MB_KEYS) + 8)
MB_TYRE = len(MB_KEYS) + 8
# After the tyre: 1.0 when a wheel may lift off the road (PlantConfig.wheel_liftoff), 0.0 for the published model.
MB_LIFTOFF = MB_TYRE + len(TYRE_KEYS)
N_MB_PARAMS = MB_LIFTOFF + 1
GRAVITY_MPS2 = 9.81


@lru_cache(maxsize=8)
def _base_vector(car: int | ParameterSet) -> tuple[float, ...]:
    p = package_parameters(car)
    v = np.zeros(N_MB_PARAMS)
    for i, name in enumerate(MB_KEYS):
        v[i] = getattr(p, name)
    v[MB_STEER_MIN], v[MB_STEER_MAX] = p.steering.min, p.steering.max
    v[MB_STEER_RATE_MIN], v[MB_STEER_RATE_MAX] = p.steering.v_min, p.steering.v_max
    v[MB_SPEED_MIN], v[MB_SPEED_MAX] = p.longitudinal.v_min, p.longitudinal.v_max
    v[MB_SPEED_SWITCH], v[MB_ACCEL_MAX] = p.longitudinal.v_switch, p.longitudinal.a_max
    for i, name in enumerate(TYRE_KEYS):
        v[MB_TYRE + i] = getattr(p.tire, name)
    return tuple(float(x) for x in v)


def pack_mb(car: int | ParameterSet, *, friction_scale: float = 1.0, mass_scale: float = 1.0,
            steer_rate_radps: float | None = None, wheel_liftoff: bool = False) -> np.ndarray:
    """MB's packed parameters, friction (PAC2002's p_dx1, p_dy1) and the sprung mass (with the total mass and the
    sprung inertias) scaled, the steering rate limit replaced (``None``: the package's 0.4 rad/s); with
    ``wheel_liftoff`` a tyre carries no load or force off the road (:func:`mb_derivatives_into`)."""
    v = np.array(_base_vector(car))
    v[MB_LIFTOFF] = 1.0 if wheel_liftoff else 0.0
    v[MB_TYRE + TYRE_KEYS.index("p_dx1")] *= friction_scale
    v[MB_TYRE + TYRE_KEYS.index("p_dy1")] *= friction_scale
    sprung = v[M_S] * mass_scale
    v[M] += sprung - v[M_S]
    v[M_S] = sprung
    for index in (I_Z, I_PHI_S, I_Y_S, I_XZ_S):
        v[index] *= mass_scale
    if steer_rate_radps is not None:
        v[MB_STEER_RATE_MIN], v[MB_STEER_RATE_MAX] = -steer_rate_radps, steer_rate_radps
    return v


@njit(cache=True)
def _steering_constraints(steering_angle, steering_velocity, p):
    if ((steering_angle <= p[MB_STEER_MIN] and steering_velocity <= 0)
            or (steering_angle >= p[MB_STEER_MAX] and steering_velocity >= 0)):
        return 0.0
    if steering_velocity <= p[MB_STEER_RATE_MIN]:
        return p[MB_STEER_RATE_MIN]
    if steering_velocity >= p[MB_STEER_RATE_MAX]:
        return p[MB_STEER_RATE_MAX]
    return steering_velocity


@njit(cache=True)
def mb_acceleration_constraints(velocity, acceleration, p):
    if velocity > p[MB_SPEED_SWITCH]:
        pos_limit = p[MB_ACCEL_MAX] * p[MB_SPEED_SWITCH] / velocity
    else:
        pos_limit = p[MB_ACCEL_MAX]
    if (velocity <= p[MB_SPEED_MIN] and acceleration <= 0) or (velocity >= p[MB_SPEED_MAX] and acceleration >= 0):
        return 0.0
    if acceleration <= -p[MB_ACCEL_MAX]:
        return -p[MB_ACCEL_MAX]
    if acceleration >= pos_limit:
        return pos_limit
    return acceleration


@njit(cache=True)
def mb_wheel_loads(x, p):
    """The tyres' normal loads [N] of MB state ``x``, in the package's order and names (lf, rf, lr, rr; its "l"
    wheels sit at -y): the spring forces of mb_derivatives, which does not clamp them at zero, so a lifted wheel
    has a negative load and its tyre pulls the road (PAC2002 scales its forces with it)."""
    r_w, t_f, t_r = p[R_W], p[T_F], p[T_R]
    out = np.empty(4)
    out[0] = (x[16] + r_w * (math.cos(x[13]) - 1) - 0.5 * t_f * math.sin(x[13])) * p[K_ZT]
    out[1] = (x[16] + r_w * (math.cos(x[13]) - 1) + 0.5 * t_f * math.sin(x[13])) * p[K_ZT]
    out[2] = (x[21] + r_w * (math.cos(x[18]) - 1) - 0.5 * t_r * math.sin(x[18])) * p[K_ZT]
    out[3] = (x[21] + r_w * (math.cos(x[18]) - 1) + 0.5 * t_r * math.sin(x[18])) * p[K_ZT]
    return out


@njit(cache=True)
def _tyre_forces(kappa, alpha, gamma, f_z, t, liftoff):
    """A tyre's combined-slip PAC2002 forces (longitudinal, lateral) [N]; none for a wheel in the air (with
    ``liftoff``, its load is 0 there: PAC2002 would divide 0 by 0)."""
    if liftoff and f_z <= 0.0:
        return 0.0, 0.0
    f0_x = formula_longitudinal(kappa, gamma, f_z, t)
    f0_y, mu_y = formula_lateral(alpha, gamma, f_z, t)
    return (formula_longitudinal_comb(kappa, alpha, f0_x, t),
            formula_lateral_comb(kappa, alpha, gamma, mu_y, f_z, f0_y, t))


@njit(cache=True, error_model="numpy")
def mb_derivatives(x, u_init, p):
    """d/dt of the MB state under [steering velocity, longitudinal acceleration] (the package's
    ``vehicle_dynamics_mb``; like it, a negative wheel speed's derivative is 0: the caller clamps the speed)."""
    f = np.empty(N_MB)
    mb_derivatives_into(x, u_init, p, f)
    return f


@njit(cache=True, error_model="numpy")  # x / 0 is inf (then a failed episode), as in the package's numpy floats
def mb_derivatives_into(x, u_init, p, f):
    """:func:`mb_derivatives` written into ``f`` (the first 29 entries): the integrator's stages allocate nothing."""
    g = GRAVITY_MPS2
    t = p[MB_TYRE - CR_TYRE:]  # the tyre functions read PAC2002's coefficients at STD's packed indices
    u0 = _steering_constraints(x[2], u_init[0], p)
    u1 = mb_acceleration_constraints(x[3], u_init[1], p)
    if abs(x[3]) < 0.1:
        beta = 0.0
    else:
        beta = math.atan(x[10] / x[3])
    vel = math.sqrt(x[3] ** 2 + x[10] ** 2)
    a, b, r_w, t_f, t_r = p[A], p[B], p[R_W], p[T_F], p[T_R]
    f_z_lf = (x[16] + r_w * (math.cos(x[13]) - 1) - 0.5 * t_f * math.sin(x[13])) * p[K_ZT]
    f_z_rf = (x[16] + r_w * (math.cos(x[13]) - 1) + 0.5 * t_f * math.sin(x[13])) * p[K_ZT]
    f_z_lr = (x[21] + r_w * (math.cos(x[18]) - 1) - 0.5 * t_r * math.sin(x[18])) * p[K_ZT]
    f_z_rr = (x[21] + r_w * (math.cos(x[18]) - 1) + 0.5 * t_r * math.sin(x[18])) * p[K_ZT]
    # The published model's tyre is a spring that also pulls (F_z = K_zt x deflection < 0 off the road) and
    # PAC2002's forces change sign with F_z: a lifted wheel would push the car the wrong way. Lift-off: a tyre
    # off the road carries no load and no force.
    liftoff = p[MB_LIFTOFF] > 0.5
    if liftoff:
        f_z_lf, f_z_rf = max(f_z_lf, 0.0), max(f_z_rf, 0.0)
        f_z_lr, f_z_rr = max(f_z_lr, 0.0), max(f_z_rr, 0.0)
    u_w_lf = (x[3] + 0.5 * t_f * x[5]) * math.cos(x[2]) + (x[10] + a * x[5]) * math.sin(x[2])
    u_w_rf = (x[3] - 0.5 * t_f * x[5]) * math.cos(x[2]) + (x[10] + a * x[5]) * math.sin(x[2])
    u_w_lr = x[3] + 0.5 * t_r * x[5]
    u_w_rr = x[3] - 0.5 * t_r * x[5]
    if u_w_lf < 0.0:
        u_w_lf *= 0
    if u_w_rf < 0.0:
        u_w_rf *= 0
    if u_w_lr < 0.0:
        u_w_lr *= 0
    if u_w_rr < 0.0:
        u_w_rr *= 0
    if abs(x[3]) < 0.1:
        s_lf = s_rf = s_lr = s_rr = 0.0
        alpha_lf = alpha_rf = alpha_lr = alpha_rr = 0.0
    else:
        s_lf = 1 - r_w * x[23] / u_w_lf
        s_rf = 1 - r_w * x[24] / u_w_rf
        s_lr = 1 - r_w * x[25] / u_w_lr
        s_rr = 1 - r_w * x[26] / u_w_rr
        alpha_lf = math.atan((x[10] + a * x[5] - x[14] * (r_w - x[16])) / (x[3] + 0.5 * t_f * x[5])) - x[2]
        alpha_rf = math.atan((x[10] + a * x[5] - x[14] * (r_w - x[16])) / (x[3] - 0.5 * t_f * x[5])) - x[2]
        alpha_lr = math.atan((x[10] - b * x[5] - x[19] * (r_w - x[21])) / (x[3] + 0.5 * t_r * x[5]))
        alpha_rr = math.atan((x[10] - b * x[5] - x[19] * (r_w - x[21])) / (x[3] - 0.5 * t_r * x[5]))
    h_s = p[H_S]
    z_slf = (h_s - r_w + x[16] - x[11]) / math.cos(x[6]) - h_s + r_w + a * x[8] + 0.5 * (x[6] - x[13]) * t_f
    z_srf = (h_s - r_w + x[16] - x[11]) / math.cos(x[6]) - h_s + r_w + a * x[8] - 0.5 * (x[6] - x[13]) * t_f
    z_slr = (h_s - r_w + x[21] - x[11]) / math.cos(x[6]) - h_s + r_w - b * x[8] + 0.5 * (x[6] - x[18]) * t_r
    z_srr = (h_s - r_w + x[21] - x[11]) / math.cos(x[6]) - h_s + r_w - b * x[8] - 0.5 * (x[6] - x[18]) * t_r
    dz_slf = x[17] - x[12] + a * x[9] + 0.5 * (x[7] - x[14]) * t_f
    dz_srf = x[17] - x[12] + a * x[9] - 0.5 * (x[7] - x[14]) * t_f
    dz_slr = x[22] - x[12] - b * x[9] + 0.5 * (x[7] - x[19]) * t_r
    dz_srr = x[22] - x[12] - b * x[9] - 0.5 * (x[7] - x[19]) * t_r
    gamma_lf = x[6] + p[D_F] * z_slf + p[E_F] * z_slf ** 2
    gamma_rf = x[6] - p[D_F] * z_srf - p[E_F] * z_srf ** 2
    gamma_lr = x[6] + p[D_R] * z_slr + p[E_R] * z_slr ** 2
    gamma_rr = x[6] - p[D_R] * z_srr - p[E_R] * z_srr ** 2
    f_x_lf, f_y_lf = _tyre_forces(s_lf, alpha_lf, gamma_lf, f_z_lf, t, liftoff)
    f_x_rf, f_y_rf = _tyre_forces(s_rf, alpha_rf, gamma_rf, f_z_rf, t, liftoff)
    f_x_lr, f_y_lr = _tyre_forces(s_lr, alpha_lr, gamma_lr, f_z_lr, t, liftoff)
    f_x_rr, f_y_rr = _tyre_forces(s_rr, alpha_rr, gamma_rr, f_z_rr, t, liftoff)
    delta_z_f = h_s - r_w + x[16] - x[11]
    delta_z_r = h_s - r_w + x[21] - x[11]
    delta_phi_f = x[6] - x[13]
    delta_phi_r = x[6] - x[18]
    dot_delta_phi_f = x[7] - x[14]
    dot_delta_phi_r = x[7] - x[19]
    dot_delta_z_f = x[17] - x[12]
    dot_delta_z_r = x[22] - x[12]
    dot_delta_y_f = x[10] + a * x[5] - x[15]
    dot_delta_y_r = x[10] - b * x[5] - x[20]
    delta_f = delta_z_f * math.sin(x[6]) - x[27] * math.cos(x[6]) - (p[H_RAF] - r_w) * math.sin(delta_phi_f)
    delta_r = delta_z_r * math.sin(x[6]) - x[28] * math.cos(x[6]) - (p[H_RAR] - r_w) * math.sin(delta_phi_r)
    dot_delta_f = ((delta_z_f * math.cos(x[6]) + x[27] * math.sin(x[6])) * x[7] + dot_delta_z_f * math.sin(x[6])
                   - dot_delta_y_f * math.cos(x[6]) - (p[H_RAF] - r_w) * math.cos(delta_phi_f) * dot_delta_phi_f)
    dot_delta_r = ((delta_z_r * math.cos(x[6]) + x[28] * math.sin(x[6])) * x[7] + dot_delta_z_r * math.sin(x[6])
                   - dot_delta_y_r * math.cos(x[6]) - (p[H_RAR] - r_w) * math.cos(delta_phi_r) * dot_delta_phi_r)
    f_raf = delta_f * p[K_RAS] + dot_delta_f * p[K_RAD]
    f_rar = delta_r * p[K_RAS] + dot_delta_r * p[K_RAD]
    m_s = p[M_S]
    f_slf = m_s * g * b / (2 * (a + b)) - z_slf * p[K_SF] - dz_slf * p[K_SDF] + (x[6] - x[13]) * p[K_TSF] / t_f
    f_srf = m_s * g * b / (2 * (a + b)) - z_srf * p[K_SF] - dz_srf * p[K_SDF] - (x[6] - x[13]) * p[K_TSF] / t_f
    f_slr = m_s * g * a / (2 * (a + b)) - z_slr * p[K_SR] - dz_slr * p[K_SDR] + (x[6] - x[18]) * p[K_TSR] / t_r
    f_srr = m_s * g * a / (2 * (a + b)) - z_srr * p[K_SR] - dz_srr * p[K_SDR] - (x[6] - x[18]) * p[K_TSR] / t_r
    sum_x = f_x_lr + f_x_rr + (f_x_lf + f_x_rf) * math.cos(x[2]) - (f_y_lf + f_y_rf) * math.sin(x[2])
    sum_n = ((f_y_lf + f_y_rf) * a * math.cos(x[2]) + (f_x_lf + f_x_rf) * a * math.sin(x[2])
             + (f_y_rf - f_y_lf) * 0.5 * t_f * math.sin(x[2]) + (f_x_lf - f_x_rf) * 0.5 * t_f * math.cos(x[2])
             + (f_x_lr - f_x_rr) * 0.5 * t_r - (f_y_lr + f_y_rr) * b)
    sum_y_s = (f_raf + f_rar) * math.cos(x[6]) + (f_slf + f_slr + f_srf + f_srr) * math.sin(x[6])
    sum_l = (0.5 * f_slf * t_f + 0.5 * f_slr * t_r - 0.5 * f_srf * t_f - 0.5 * f_srr * t_r
             - f_raf / math.cos(x[6]) * (h_s - x[11] - r_w + x[16] - (p[H_RAF] - r_w) * math.cos(x[13]))
             - f_rar / math.cos(x[6]) * (h_s - x[11] - r_w + x[21] - (p[H_RAR] - r_w) * math.cos(x[18])))
    sum_z_s = (f_slf + f_slr + f_srf + f_srr) * math.cos(x[6]) - (f_raf + f_rar) * math.sin(x[6])
    sum_m_s = (a * (f_slf + f_srf) - b * (f_slr + f_srr) + ((f_x_lf + f_x_rf) * math.cos(x[2])
               - (f_y_lf + f_y_rf) * math.sin(x[2]) + f_x_lr + f_x_rr) * (h_s - x[11]))
    sum_l_uf = (0.5 * f_srf * t_f - 0.5 * f_slf * t_f - f_raf * (p[H_RAF] - r_w)
                + f_z_lf * (r_w * math.sin(x[13]) + 0.5 * t_f * math.cos(x[13]) - p[K_LT] * f_y_lf)
                - f_z_rf * (-r_w * math.sin(x[13]) + 0.5 * t_f * math.cos(x[13]) + p[K_LT] * f_y_rf)
                - ((f_y_lf + f_y_rf) * math.cos(x[2]) + (f_x_lf + f_x_rf) * math.sin(x[2])) * (r_w - x[16]))
    sum_l_ur = (0.5 * f_srr * t_r - 0.5 * f_slr * t_r - f_rar * (p[H_RAR] - r_w)
                + f_z_lr * (r_w * math.sin(x[18]) + 0.5 * t_r * math.cos(x[18]) - p[K_LT] * f_y_lr)
                - f_z_rr * (-r_w * math.sin(x[18]) + 0.5 * t_r * math.cos(x[18]) + p[K_LT] * f_y_rr)
                - (f_y_lr + f_y_rr) * (r_w - x[21]))
    sum_z_uf = f_z_lf + f_z_rf + f_raf * math.sin(x[6]) - (f_slf + f_srf) * math.cos(x[6])
    sum_z_ur = f_z_lr + f_z_rr + f_rar * math.sin(x[6]) - (f_slr + f_srr) * math.cos(x[6])
    sum_y_uf = ((f_y_lf + f_y_rf) * math.cos(x[2]) + (f_x_lf + f_x_rf) * math.sin(x[2])
                - f_raf * math.cos(x[6]) - (f_slf + f_srf) * math.sin(x[6]))
    sum_y_ur = (f_y_lr + f_y_rr) - f_rar * math.cos(x[6]) - (f_slr + f_srr) * math.sin(x[6])

    if abs(x[3]) < 0.1:
        lwb = a + b
        beta_ks = math.atan(math.tan(x[2]) * b / lwb)
        f[0] = x[3] * math.cos(beta_ks + x[4])
        f[1] = x[3] * math.sin(beta_ks + x[4])
        f[2] = u0
        f[3] = u1
        f[4] = x[3] * math.cos(beta_ks) * math.tan(x[2]) / lwb
        d_beta = (b * u0) / (lwb * math.cos(x[2]) ** 2 * (1 + (math.tan(x[2]) ** 2 * b / lwb) ** 2))
        f[5] = 1 / lwb * (u1 * math.cos(x[6]) * math.tan(x[2]) - x[3] * math.sin(x[6]) * d_beta * math.tan(x[2])
                          + x[3] * math.cos(x[6]) * u0 / math.cos(x[2]) ** 2)
    else:
        f[0] = math.cos(beta + x[4]) * vel
        f[1] = math.sin(beta + x[4]) * vel
        f[2] = u0
        f[3] = 1 / p[M] * sum_x + x[5] * x[10]
        f[4] = x[5]
        f[5] = 1 / (p[I_Z] - p[I_XZ_S] ** 2 / p[I_PHI_S]) * (sum_n + p[I_XZ_S] / p[I_PHI_S] * sum_l)
    f[6] = x[7]
    f[7] = 1 / (p[I_PHI_S] - p[I_XZ_S] ** 2 / p[I_Z]) * (p[I_XZ_S] / p[I_Z] * sum_n + sum_l)
    f[8] = x[9]
    f[9] = 1 / p[I_Y_S] * sum_m_s
    f[10] = 1 / m_s * sum_y_s - x[5] * x[3]
    f[11] = x[12]
    f[12] = g - 1 / m_s * sum_z_s
    f[13] = x[14]
    f[14] = 1 / p[I_UF] * sum_l_uf
    f[15] = 1 / p[M_UF] * sum_y_uf - x[5] * x[3]
    f[16] = x[17]
    f[17] = g - 1 / p[M_UF] * sum_z_uf
    f[18] = x[19]
    f[19] = 1 / p[I_UR] * sum_l_ur
    f[20] = 1 / p[M_UR] * sum_y_ur - x[5] * x[3]
    f[21] = x[22]
    f[22] = g - 1 / p[M_UR] * sum_z_ur
    if u1 > 0:
        t_b = 0.0
        t_e = p[M] * r_w * u1
    else:
        t_b = p[M] * r_w * u1
        t_e = 0.0
    iw = p[I_Y_W]
    f[23] = 1 / iw * (-r_w * f_x_lf + 0.5 * p[T_SB] * t_b + 0.5 * p[T_SE] * t_e)
    f[24] = 1 / iw * (-r_w * f_x_rf + 0.5 * p[T_SB] * t_b + 0.5 * p[T_SE] * t_e)
    f[25] = 1 / iw * (-r_w * f_x_lr + 0.5 * (1 - p[T_SB]) * t_b + 0.5 * (1 - p[T_SE]) * t_e)
    f[26] = 1 / iw * (-r_w * f_x_rr + 0.5 * (1 - p[T_SB]) * t_b + 0.5 * (1 - p[T_SE]) * t_e)
    for i in range(23, 27):
        if x[i] < 0.0:
            f[i] = 0.0
    f[27] = dot_delta_y_f
    f[28] = dot_delta_y_r
