"""The environment's observation and action: their layouts, units and Gymnasium spaces.

Observation (float64, one vector a control step), what the controller of the paper reads (section II-B, III):

=====  ===============  ======  ==============================================================================
index  name             unit    what
=====  ===============  ======  ==============================================================================
0      V_mps            m/s     speed, as the sensors report it (with the episode's noise)
1      beta_rad         rad     sideslip, sensed
2      r_radps          rad/s   yaw rate, sensed
3      e_m              m       lateral error to the tracked circle (> 0 right of the path), sensed
4      dpsi_rad         rad     course error to the tracked circle, sensed
5      c                -       the tracked circle's trigger quantity, arc to P0 / (2 pi R) (paper eq. 8)
6      delta_rad        rad     front steering angle (the actuator's position)
7      Fxr_n            N       rear drive force (the actuator's position)
8      V_ref_mps        m/s     reference speed of the tracked drift (V_eq + dV, paper eq. 10)
9      beta_ref_rad     rad     reference sideslip
10     r_ref_radps      rad/s   reference yaw rate
11-16  phase one-hot    -       left drift, inertia left->right, right drift, inertia right->left, final left
                                drift, finished (driftlab.core.planner.Phase)
=====  ===============  ======  ==============================================================================

The reference (8-10) is the one the episode's trajectory records: the tracked circle's drift equilibrium with
theta's speed correction, moved by the MPC's disturbance estimate when the MPC itself drives
(driftlab.core.controller.drift_reference; the estimate stays zero under any other policy).

Action (float64): [steering command delta rad, rear drive command Fxr N], the commands the MPC sends (the paper's
steering feedback k e_la included), bounded as the MPC bounds them: |delta| <= mpc.steer_limit_rad, Fxr in
[mpc.drive_min_n, mpc.drive_max_n].
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from driftlab.core.mpc import KN, QpArrays
from driftlab.core.planner import Phase

OBSERVATION_NAMES = ("V_mps", "beta_rad", "r_radps", "e_m", "dpsi_rad", "c", "delta_rad", "Fxr_n", "V_ref_mps",
                     "beta_ref_rad", "r_ref_radps", *(f"phase_{phase.name.lower()}" for phase in Phase))
(O_SPEED, O_SIDESLIP, O_YAW_RATE, O_E, O_DPSI, O_C, O_STEER, O_DRIVE, O_SPEED_REF, O_SIDESLIP_REF,
 O_YAW_RATE_REF, O_PHASE) = range(12)
N_OBSERVATION = len(OBSERVATION_NAMES)
ACTION_NAMES = ("delta_cmd_rad", "Fxr_cmd_n")


def observation_space() -> spaces.Box:
    """Unbounded but for c in [0, 1] and the phase's one-hot entries in {0, 1}."""
    low = np.full(N_OBSERVATION, -np.inf)
    high = np.full(N_OBSERVATION, np.inf)
    low[O_C], high[O_C] = 0.0, 1.0
    low[O_PHASE:], high[O_PHASE:] = 0.0, 1.0
    return spaces.Box(low, high, dtype=np.float64)


def action_bounds(qa: QpArrays) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of [delta rad, Fxr N]: the MPC's own limits, the drive converted from the QP's kN as the loop
    converts it (so that every command the MPC sends lies inside, to the bit)."""
    low = np.array([-qa.steer_limit_rad, qa.drive_min_kn / KN])
    high = np.array([qa.steer_limit_rad, qa.drive_max_kn / KN])
    return low, high


def action_space(qa: QpArrays) -> spaces.Box:
    low, high = action_bounds(qa)
    return spaces.Box(low, high, dtype=np.float64)
