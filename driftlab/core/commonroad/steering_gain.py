"""How strongly a car's yaw rate answers the steering in its drift, on the car and on the controller's model; and
the model's front grip that makes the two agree.

Why: the multi-body car's front tyres are far from their peak in its drift, so a 0.02 rad step of steering
raises its yaw rate by 0.106 rad/s (mean over 0.1..0.3 s); the model fitted to its drift
(driftlab.core.commonroad.model_fit) with the front grip it reads off the tyre has its front axle near saturation
and answers with 0.0087. An MPC that believes the steering 12x weaker than it is steers 12x too hard: MB's drift
then oscillates at ~2.7 Hz and spins out. A front/rear grip split (``VehicleParams.front_grip_scale``) moves where
on its curve the model's front tyre sits without moving the drift itself (friction and offsets are refitted for
each split), and so sets the gain.

The response is measured as a practitioner would on a car: from its steady drift, hold the drive, step the
steering command, and read the yaw rate change averaged over 0.1..0.3 s. The model is fed the steering angle the
car's servo actually produced, so actuator lag is no part of the comparison.
"""

from __future__ import annotations

import numpy as np

from driftlab.core.plant import DRIVE, SIDESLIP, SPEED, STEER, YAW_RATE, PlantConfig, make_plant
from driftlab.core.vehicle import VehicleParams, drift_derivatives, pack_params

STEP_RAD = 0.02  # toward less countersteer: small enough to stay near the drift, large enough to read
PERIOD_S = 0.05
WINDOW_S = (0.1, 0.3)
_MODEL_DT_S = 0.001


def car_yaw_response(plant_config: PlantConfig, drift, radius_m: float) -> tuple[float, np.ndarray]:
    """(mean yaw-rate change over WINDOW_S after a STEP_RAD steering step from the car's left-hand ``drift``
    [rad/s], the car's steering angle every PERIOD_S during it [rad])."""
    plant = make_plant(plant_config, VehicleParams())
    if hasattr(plant, "start_in_drift_of"):
        plant.start_in_drift_of(radius_m, drift.sideslip_rad)
    loop = np.zeros(8)
    loop[SPEED], loop[SIDESLIP], loop[YAW_RATE] = drift.speed_mps, drift.sideslip_rad, drift.yaw_rate_radps
    loop[STEER], loop[DRIVE] = drift.steer_rad, drift.drive_n
    runs = {}
    for step in (0.0, STEP_RAD):
        state = plant.start_state(loop)
        rows = []
        for _ in range(round(WINDOW_S[1] / PERIOD_S)):
            state = plant.step(state, drift.steer_rad + step, drift.drive_n, PERIOD_S)
            rows.append((state[YAW_RATE], state[STEER]))
        runs[step] = np.array(rows)
    return _window_mean(runs[STEP_RAD][:, 0] - runs[0.0][:, 0]), runs[STEP_RAD][:, 1]


def model_yaw_response(vehicle: VehicleParams, drift, steer_rad: np.ndarray) -> float:
    """The model's mean yaw-rate change over WINDOW_S when its steering follows ``steer_rad`` (sampled every
    PERIOD_S, linear between) instead of holding the drift's, from the same drift with the same drive."""
    p = pack_params(vehicle)
    times = PERIOD_S * np.arange(len(steer_rad) + 1)
    angles = np.r_[drift.steer_rad, steer_rad]
    responses = []
    for steering in (np.full_like(angles, drift.steer_rad), angles):
        x = np.array([drift.speed_mps, drift.sideslip_rad, drift.yaw_rate_radps])
        yaw = []
        for k in range(round(times[-1] / _MODEL_DT_S)):
            t = k * _MODEL_DT_S
            x = x + _MODEL_DT_S * np.array(drift_derivatives(x[0], x[1], x[2], np.interp(t, times, steering),
                                                            drift.drive_n, p))
            if (k + 1) % round(PERIOD_S / _MODEL_DT_S) == 0:
                yaw.append(x[2])
        responses.append(np.array(yaw))
    return _window_mean(responses[1] - responses[0])


def _window_mean(change: np.ndarray) -> float:
    t = PERIOD_S * np.arange(1, len(change) + 1)
    inside = (t >= WINDOW_S[0] - 1e-9) & (t <= WINDOW_S[1] + 1e-9)
    return float(np.mean(change[inside]))
