"""How strongly a car's yaw rate answers the steering (or the drive) in its drift, on the car and on the controller's
model; and the model's front grip that makes the steering's two answers agree.

Why: the multi-body car's front tyres are far from their peak in its drift, so a 0.02 rad step of steering
raises its yaw rate by 0.106 rad/s (mean over 0.1..0.3 s); the model fitted to its drift
(driftlab.core.commonroad.model_fit) with the front grip it reads off the tyre has its front axle near saturation
and answers with 0.026 (0.0087 without the rear friction circle). An MPC that believes the steering 4x weaker than
it is steers 4x too hard: MB's drift then oscillates and spins out. A front/rear grip split
(``VehicleParams.front_grip_scale``) moves where on its curve the model's front tyre sits without moving the drift
itself (friction and offsets are refitted for each split), and so sets the gain.

The response is measured as a practitioner would on a car: from its steady drift, hold the drive, step the
steering command, and read the yaw rate change averaged over 0.1..0.3 s. The model is fed the steering angle the
car's servo actually produced, so actuator lag is no part of the comparison. A step of the drive instead (500 N)
raises MB's yaw rate by 0.027 rad/s; the fitted model's by 0.041 with the rear friction circle, and lowers it by
0.006 without (tests/core/test_commonroad.py).
"""

from __future__ import annotations

import numpy as np

from driftlab.core.plant import DRIVE, SIDESLIP, SPEED, STEER, YAW_RATE
from driftlab.core.vehicle import VehicleParams, drift_derivatives, pack_params

STEP_RAD = 0.02  # toward less countersteer: small enough to stay near the drift, large enough to read
DRIVE_STEP_N = 500.0  # more drive: about 15 % of the drift's, small enough to stay near it
PERIOD_S = 0.05
WINDOW_S = (0.1, 0.3)
_MODEL_DT_S = 0.001


def car_yaw_response(plant, drift, radius_m: float, steer_step_rad: float = STEP_RAD,
                     drive_step_n: float = 0.0) -> tuple[float, np.ndarray, np.ndarray]:
    """(mean yaw-rate change over WINDOW_S after a step of the steering and/or drive command from the car's
    left-hand ``drift`` [rad/s], the car's steering angle [rad] and drive force [N] every PERIOD_S during it).
    ``plant``: the car's stepper (PlantType.build)."""
    if hasattr(plant, "start_in_drift_of"):
        plant.start_in_drift_of(radius_m, drift.sideslip_rad)
    loop = np.zeros(8)
    loop[SPEED], loop[SIDESLIP], loop[YAW_RATE] = drift.speed_mps, drift.sideslip_rad, drift.yaw_rate_radps
    loop[STEER], loop[DRIVE] = drift.steer_rad, drift.drive_n
    runs = {}
    for step in (0.0, 1.0):
        state = plant.start_state(loop)
        rows = []
        for _ in range(round(WINDOW_S[1] / PERIOD_S)):
            state = plant.step(state, drift.steer_rad + step * steer_step_rad, drift.drive_n + step * drive_step_n,
                               PERIOD_S)
            rows.append((state[YAW_RATE], state[STEER], state[DRIVE]))
        runs[step] = np.array(rows)
    return _window_mean(runs[1.0][:, 0] - runs[0.0][:, 0]), runs[1.0][:, 1], runs[1.0][:, 2]


def model_yaw_response(vehicle: VehicleParams, drift, steer_rad: np.ndarray, drive_n: np.ndarray | None = None
                       ) -> float:
    """The model's mean yaw-rate change over WINDOW_S when its steering follows ``steer_rad`` (and its drive
    ``drive_n``; sampled every PERIOD_S, linear between) instead of holding the drift's, from the same drift."""
    p = pack_params(vehicle)
    times = PERIOD_S * np.arange(len(steer_rad) + 1)
    angles = np.r_[drift.steer_rad, steer_rad]
    forces = np.full_like(angles, drift.drive_n) if drive_n is None else np.r_[drift.drive_n, drive_n]
    responses = []
    for steering, drive in ((np.full_like(angles, drift.steer_rad), np.full_like(angles, drift.drive_n)),
                            (angles, forces)):
        x = np.array([drift.speed_mps, drift.sideslip_rad, drift.yaw_rate_radps])
        yaw = []
        for k in range(round(times[-1] / _MODEL_DT_S)):
            t = k * _MODEL_DT_S
            x = x + _MODEL_DT_S * np.array(drift_derivatives(x[0], x[1], x[2], np.interp(t, times, steering),
                                                            np.interp(t, times, drive), p))
            if (k + 1) % round(PERIOD_S / _MODEL_DT_S) == 0:
                yaw.append(x[2])
        responses.append(np.array(yaw))
    return _window_mean(responses[1] - responses[0])


def _window_mean(change: np.ndarray) -> float:
    t = PERIOD_S * np.arange(1, len(change) + 1)
    inside = (t >= WINDOW_S[0] - 1e-9) & (t <= WINDOW_S[1] + 1e-9)
    return float(np.mean(change[inside]))
