"""CommonRoad's STD through the package's own Python functions, as a registered plant (plant.model
``commonroad_std_reference``): the reference the compiled port is checked against at the level of whole
episodes, and an example of a plant that brings no compiled step (driftlab.core.plants.register_plant).

About 0.1 ms of Python per derivative: ~60x slower than ``commonroad_std``; for checks, not for tuning.
"""

from __future__ import annotations

import numpy as np

from driftlab.core.commonroad.parameters import pack_commonroad, package_parameters
from driftlab.core.commonroad.plant import (
    DRIVE_ACTUATOR,
    N_STD_PLANT_STATES,
    OMEGA_F,
    OMEGA_R,
    std_start_state,
)
from driftlab.core.integrator import rk4_stage, rk4_update
from driftlab.core.plant import (
    A_DRIVE_LAG,
    A_DRIVE_RATE,
    A_STEER_LAG,
    A_STEER_RATE,
    DRIVE,
    HEADING,
    PLANT_EXTERNAL,
    SIDESLIP,
    SPEED,
    STEER,
    X_POS,
    Y_POS,
    YAW_RATE,
    PlantConfig,
)


def _rate(actual: float, command: float, lag_s: float, limit: float) -> float:
    return min(max((command - actual) / lag_s, -limit), limit)


class ReferenceStdPlant:
    kind = PLANT_EXTERNAL

    def __init__(self, config: PlantConfig, car) -> None:
        from dataclasses import replace

        self.config = config
        base = package_parameters(car)
        # The package's object, with the plant's steering rate and scales (as pack_commonroad applies them).
        self.p = replace(base, m=base.m * config.mass_scale, I_z=base.I_z * config.mass_scale,
                         steering=replace(base.steering, v_min=-config.steer_rate_radps, v_max=config.steer_rate_radps),
                         tire=replace(base.tire, p_dx1=base.tire.p_dx1 * config.friction_scale,
                                      p_dy1=base.tire.p_dy1 * config.friction_scale))
        self.act = config.actuator_params()
        self.cp = pack_commonroad(car, friction_scale=config.friction_scale,
                                  mass_scale=config.mass_scale, steer_rate_radps=config.steer_rate_radps)

    def start_state(self, loop_state: np.ndarray) -> np.ndarray:
        return std_start_state(loop_state, self.cp, self.config.initial_rear_slip)

    def _derivatives(self, z: np.ndarray, steer_cmd: float, drive_cmd: float) -> np.ndarray:
        from vehiclemodels.vehicle_dynamics_std import vehicle_dynamics_std

        u = [_rate(z[2], steer_cmd, self.act[A_STEER_LAG], self.act[A_STEER_RATE]), z[9] / self.p.m]
        out = np.empty(10)
        out[:9] = vehicle_dynamics_std(list(z[:9]), u, self.p)  # a copy: the package edits its argument
        out[9] = _rate(z[9], drive_cmd, self.act[A_DRIVE_LAG], self.act[A_DRIVE_RATE])
        return out

    def step(self, state: np.ndarray, steer_cmd_rad: float, drive_cmd_n: float, duration_s: float) -> np.ndarray:
        from vehiclemodels.utils.acceleration_constraints import acceleration_constraints

        s = state
        z = np.array([s[X_POS], s[Y_POS], s[STEER], s[SPEED], s[HEADING], s[YAW_RATE], s[SIDESLIP], s[OMEGA_F],
                      s[OMEGA_R], s[DRIVE_ACTUATOR]])
        n_sub = max(1, int(round(duration_s / self.config.substep_s)))
        h = duration_s / n_sub
        for _ in range(n_sub):
            k1 = self._derivatives(z, steer_cmd_rad, drive_cmd_n)
            k2 = self._derivatives(rk4_stage(z, 0.5 * h, k1), steer_cmd_rad, drive_cmd_n)
            k3 = self._derivatives(rk4_stage(z, 0.5 * h, k2), steer_cmd_rad, drive_cmd_n)
            k4 = self._derivatives(rk4_stage(z, h, k3), steer_cmd_rad, drive_cmd_n)
            z = rk4_update(z, h, k1, k2, k3, k4)
            z[7], z[8] = max(0.0, z[7]), max(0.0, z[8])
        out = np.empty(N_STD_PLANT_STATES)
        out[X_POS], out[Y_POS], out[HEADING] = z[0], z[1], z[4]
        out[SPEED], out[SIDESLIP], out[YAW_RATE], out[STEER] = z[3], z[6], z[5], z[2]
        out[DRIVE] = self.p.m * acceleration_constraints(z[3], z[9] / self.p.m, self.p.longitudinal)
        out[OMEGA_F], out[OMEGA_R], out[DRIVE_ACTUATOR] = z[7], z[8], z[9]
        return out
