"""The higher-fidelity plant that stands in for CarSim.

The same single-track body as the controller's model (:func:`driftlab.core.vehicle.drift_derivatives`) plus
what the paper's model leaves out, each a named setting in :class:`PlantConfig`:

- its own car: friction, mass, yaw inertia and tyre B/C scaled against the controller's vehicle;
- the rear friction circle (drive force eats lateral capacity);
- longitudinal load transfer through the CG height;
- steering and drive actuators with first-order lag and rate limits;
- pose kinematics (x, y, psi).

``PlantConfig.nominal()`` switches every difference off: the plant then equals the 3-state model.

Integration: classical RK4 at ``substep_s`` (default 5 ms). The fastest mode is the actuator lag
(tau >= 20 ms, eigenvalue -50 1/s), |lambda h| <= 0.25 at 5 ms. ``benchmarks/bench_plant.py`` prints the
error against a 0.5 ms reference (4e-8 on [V, beta, r] over 5 s for the default plant).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numba import njit

from driftlab.core.errors import ConfigError
from driftlab.core.integrator import rk4_stage_into, rk4_update_into
from driftlab.core.validation import check_ranges
from driftlab.core.vehicle import VehicleParams, drift_derivatives, pack_params, pose_derivatives

# Plant state layout.
X_POS, Y_POS, HEADING, SPEED, SIDESLIP, YAW_RATE, STEER, DRIVE = range(8)
N_PLANT_STATES = 8

# Per-episode variation settings and their largest allowed value (see PlantConfig).
VARIATION_LIMITS: dict[str, float] = {
    "friction_spread": 0.3, "mass_spread": 0.3, "steer_lag_spread_s": 0.5, "initial_speed_spread_mps": 2.0,
    "initial_sideslip_spread_rad": 0.2, "initial_yaw_rate_spread_radps": 0.2, "noise_speed_mps": 1.0,
    "noise_sideslip_rad": 0.1, "noise_yaw_rate_radps": 0.1, "noise_position_m": 1.0, "noise_heading_rad": 0.1}

PLANT_LIMITS: dict[str, tuple[float, float]] = {
    "friction_scale": (0.5, 2.0), "mass_scale": (0.5, 2.0), "yaw_inertia_scale": (0.5, 2.0),
    "tyre_b_scale": (0.5, 2.0), "tyre_c_scale": (0.5, 1.6), "cg_height_m": (0.0, 1.5),
    "steer_lag_s": (0.0, 0.5), "steer_rate_radps": (0.1, 100.0), "drive_lag_s": (0.0, 1.0),
    "drive_rate_nps": (100.0, 1e7), "substep_s": (1e-4, 0.01), "initial_rear_slip": (-3.0, 0.0),
    **{name: (0.0, hi) for name, hi in VARIATION_LIMITS.items()},
}

# Actuator parameter layout: [steer lag s, steer rate rad/s, drive lag s, drive rate N/s].
A_STEER_LAG, A_STEER_RATE, A_DRIVE_LAG, A_DRIVE_RATE = range(4)

# Where the episode loop steps a plant (a stepper's ``kind``): inside its compiled kernel (DriftLab's own, CommonRoad's
# STD), or, for any other (MB, a user's own car), by calling the plant's ``step`` once a control step. The episode
# loop, planner, controller, failure rules and J are the same code either way. Which plants exist, and what each
# one brings, is the plant catalog's (driftlab.core.plants).
PLANT_DRIFTLAB, PLANT_COMMONROAD_STD, PLANT_EXTERNAL = range(3)


@dataclass(frozen=True)
class PlantConfig:
    """What the plant adds to, or changes from, the controller's model. Defaults: the default plant.

    The default plant has 10% more friction, a 10% larger tyre shape factor C, the rear friction circle,
    longitudinal load transfer through a 0.45 m CG, and 30 ms / 50 ms actuator lags with rate limits. mu and C
    were chosen together so that the plant can hold the paper's drift at all: with load transfer and the
    model's C there is no countersteer drift at R = 44 m for any beta (the front runs out of load), so the
    paper's Table I, a fit to a real car, could not have come from such a car. Its own equilibrium at
    beta = -0.4 differs from the model's by dV -0.07 m/s, ddelta +0.022 rad, dFxr +108 N.

    Attributes:
        friction_scale: plant mu / model mu.
        mass_scale: plant m / model m.
        yaw_inertia_scale: plant Iz / model Iz.
        tyre_b_scale: plant B / model B.
        tyre_c_scale: plant C / model C.
        friction_circle: couple rear Fx and Fy through the friction circle.
        load_transfer: shift axle loads by m ax h / L.
        cg_height_m: CG height for load transfer [m].
        steer_lag_s: steering actuator time constant [s] (0: follows the command at once).
        steer_rate_radps: steering actuator rate limit [rad/s].
        drive_lag_s: drive-force actuator time constant [s] (0: follows at once).
        drive_rate_nps: drive-force rate limit [N/s].
        substep_s: RK4 integration step [s].
        model: "driftlab" (this module's plant) or "commonroad_std" (CommonRoad's STD, the parameter set
            ``commonroad_vehicle``: 2 BMW 320i, 3 VW Vanagon; 1, front-wheel drive, is refused). For a
            CommonRoad plant, friction_scale scales PAC2002's peak friction, mass_scale its mass and yaw inertia,
            the actuator settings shape the steering servo and the drive mapping (driftlab.core.commonroad.plant);
            the tyre and load settings above do not apply and must stay at 1 / off.
        commonroad_vehicle: CommonRoad parameter set (2 or 3).
        initial_rear_slip: a CommonRoad plant's rear wheel slip ratio at the start (negative: spinning) [-].
        locked_differential: MB's rear wheels on one shaft (the package gives each half the drive torque, an open
            differential: in a 1 g drift the inner rear wheel unloads, its normal force falls below zero within
            0.3 s, and it spins up, 78 -> 185 rad/s in 0.35 s, so no power-on drift can be held; drift cars lock
            or weld theirs). STD has one rear wheel: this does not apply.
        model_drive_coupling: the controller's model of a CommonRoad car takes the rear friction circle, its
            coupling (VehicleParams.rear_coupling) matched to the car's yaw answer to a drive step: the car's rear
            slides further under more drive, the paper's model does not answer (driftlab.core.commonroad.model_fit).
            Off: the paper's independent rear forces (STD) or the whole circle (MB).
        wheel_liftoff: MB's wheels may leave the road: a tyre whose spring would pull (a negative normal load)
            carries no load and no force. The published model has no lift-off: its tyre pulls the road, and PAC2002's
            forces change sign with the load, so in a ~1 g drift the unloaded inner front wheel pushes the car the
            wrong way (docs/results.md, "Where MB is valid"). Off: the package's model as published, bit for bit.

    Per-episode variation, drawn from the episode's seed (:mod:`driftlab.core.variation`); a real car never
    drives the same episode twice. Spreads are half-widths of uniform draws, noise levels standard deviations
    of Gaussian measurement noise (an RTK GNSS/INS with an optical slip sensor). All zero in :meth:`nominal`.
    The defaults are modest because they were set when the controller's basin was small (before the offset-free
    controller, with friction +-1%, mass +-2%, sideslip noise 0.001 rad and a 0.003 rad start spread together,
    none of 28 theta in the default bounds completed 95% of 16 seeds, benchmarks/variation_sweep.py); they
    are kept so that stored jobs and their figures stay comparable.
        friction_spread: relative spread of friction, mu x (1 + U(-s, s)) [-].
        mass_spread: relative spread of mass (and with it yaw inertia) [-].
        steer_lag_spread_s: spread of the steering time constant [s].
        initial_speed_spread_mps, initial_sideslip_spread_rad, initial_yaw_rate_spread_radps: spread of the
            start state around the start equilibrium.
        noise_speed_mps, noise_sideslip_rad, noise_yaw_rate_radps: noise on the measured V, beta, r.
        noise_position_m, noise_heading_rad: noise on the measured x, y and psi (hence on e and dpsi).
    """

    friction_scale: float = 1.1
    mass_scale: float = 1.0
    yaw_inertia_scale: float = 1.0
    tyre_b_scale: float = 1.0
    tyre_c_scale: float = 1.1
    friction_circle: bool = True
    load_transfer: bool = True
    cg_height_m: float = 0.45
    steer_lag_s: float = 0.03
    steer_rate_radps: float = 8.0
    drive_lag_s: float = 0.05
    drive_rate_nps: float = 40000.0
    substep_s: float = 0.005
    friction_spread: float = 0.01
    mass_spread: float = 0.02
    steer_lag_spread_s: float = 0.002
    initial_speed_spread_mps: float = 0.1
    initial_sideslip_spread_rad: float = 0.002
    initial_yaw_rate_spread_radps: float = 0.004
    noise_speed_mps: float = 0.01
    noise_sideslip_rad: float = 0.0005
    noise_yaw_rate_radps: float = 0.002
    noise_position_m: float = 0.01
    noise_heading_rad: float = 0.002
    model: str = "driftlab"
    commonroad_vehicle: int = 2
    initial_rear_slip: float = -0.5
    locked_differential: bool = True
    model_drive_coupling: bool = False
    wheel_liftoff: bool = False

    def __post_init__(self) -> None:
        check_ranges(self, "plant", PLANT_LIMITS)
        if not isinstance(self.model, str) or not self.model:
            raise ConfigError(f"plant.model must be a plant's name, got {self.model!r}", field="plant.model")
        if self.steer_lag_spread_s > self.steer_lag_s:
            raise ConfigError(f"plant.steer_lag_spread_s must be in [0, plant.steer_lag_s = {self.steer_lag_s}], "
                              f"got {self.steer_lag_spread_s!r}")
        for name in ("friction_circle", "load_transfer", "locked_differential", "model_drive_coupling",
                     "wheel_liftoff"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"plant.{name} must be true or false, got {getattr(self, name)!r}")

    @classmethod
    def nominal(cls) -> PlantConfig:
        """A plant equal to the controller's model (ideal actuators, same car)."""
        no_variation: dict[str, Any] = dict.fromkeys(VARIATION_LIMITS, 0.0)
        return cls(friction_scale=1.0, tyre_c_scale=1.0, friction_circle=False, load_transfer=False,
                   steer_lag_s=0.0, steer_rate_radps=100.0, drive_lag_s=0.0, drive_rate_nps=1e7, **no_variation)

    @property
    def varies(self) -> bool:
        """Whether episodes of this plant differ by seed."""
        return any(getattr(self, name) > 0.0 for name in VARIATION_LIMITS)

    def vehicle(self, model_vehicle: VehicleParams) -> VehicleParams:
        """The plant's own car: the controller's vehicle with this config's scale factors."""
        scaled = model_vehicle.scaled(friction=self.friction_scale, mass_kg=self.mass_scale,
                                      yaw_inertia_kgm2=self.yaw_inertia_scale, tyre_b=self.tyre_b_scale,
                                      tyre_c=self.tyre_c_scale)
        # The plant's own car: a model's equilibrium offsets are the model's, not the car's, and the plant's tyre
        # coupling is plant.friction_circle, not the model's.
        return replace(scaled, cg_height_m=self.cg_height_m, steer_offset_rad=0.0, drive_offset_n=0.0,
                       steer_offset_right_rad=0.0, drive_offset_right_n=0.0, rear_friction_circle=False,
                       rear_coupling=1.0)

    def packed_params(self, model_vehicle: VehicleParams) -> np.ndarray:
        """Parameter vector for the compiled dynamics of this plant."""
        return pack_params(self.vehicle(model_vehicle), friction_circle=self.friction_circle,
                           load_transfer=self.load_transfer)

    def actuator_params(self) -> np.ndarray:
        return np.array([self.steer_lag_s, self.steer_rate_radps, self.drive_lag_s, self.drive_rate_nps])


@njit(cache=True)
def _actuator_rate(actual, command, lag_s, rate_limit):
    return min(max((command - actual) / lag_s, -rate_limit), rate_limit)


@njit(cache=True)
def plant_derivatives_into(ds, s, steer_cmd, drive_cmd, p, act):
    """d/dt of the plant state (layout X_POS ... DRIVE) under held commands, written into ``ds``."""
    dv, dbeta, dr = drift_derivatives(s[SPEED], s[SIDESLIP], s[YAW_RATE], s[STEER], s[DRIVE], p)
    dx, dy, dpsi = pose_derivatives(s[SPEED], s[SIDESLIP], s[YAW_RATE], s[HEADING])
    ds[X_POS] = dx
    ds[Y_POS] = dy
    ds[HEADING] = dpsi
    ds[SPEED] = dv
    ds[SIDESLIP] = dbeta
    ds[YAW_RATE] = dr
    ds[STEER] = (_actuator_rate(s[STEER], steer_cmd, act[A_STEER_LAG], act[A_STEER_RATE])
                 if act[A_STEER_LAG] > 0.0 else 0.0)
    ds[DRIVE] = (_actuator_rate(s[DRIVE], drive_cmd, act[A_DRIVE_LAG], act[A_DRIVE_RATE])
                 if act[A_DRIVE_LAG] > 0.0 else 0.0)


@njit(cache=True)
def plant_step(state, steer_cmd, drive_cmd, duration_s, substep_s, p, act):
    """Advance the plant by ``duration_s`` with commands held (zero-order hold), RK4 at ``substep_s``.

    An actuator with zero lag moves to its command at once, as far as its rate limit allows.
    Returns a new state array; the argument is not modified.
    """
    s = state.copy()
    if act[A_STEER_LAG] <= 0.0:
        reach = act[A_STEER_RATE] * duration_s
        s[STEER] += min(max(steer_cmd - s[STEER], -reach), reach)
    if act[A_DRIVE_LAG] <= 0.0:
        reach = act[A_DRIVE_RATE] * duration_s
        s[DRIVE] += min(max(drive_cmd - s[DRIVE], -reach), reach)
    n_sub = max(1, int(round(duration_s / substep_s)))
    h = duration_s / n_sub
    # The stages in buffers allocated once a step: ~2.8 us of a 50 ms step's 13 us were its 80
    # allocations (the same arithmetic, the same bits).
    k1, k2, k3, k4, stage = np.empty((5, s.shape[0]))
    for _ in range(n_sub):
        plant_derivatives_into(k1, s, steer_cmd, drive_cmd, p, act)
        rk4_stage_into(stage, s, 0.5 * h, k1)
        plant_derivatives_into(k2, stage, steer_cmd, drive_cmd, p, act)
        rk4_stage_into(stage, s, 0.5 * h, k2)
        plant_derivatives_into(k3, stage, steer_cmd, drive_cmd, p, act)
        rk4_stage_into(stage, s, h, k3)
        plant_derivatives_into(k4, stage, steer_cmd, drive_cmd, p, act)
        rk4_update_into(s, h, k1, k2, k3, k4)
    return s


class Plant:
    """A plant instance, what the episode loop steps: configuration resolved against the controller's vehicle.

    Attributes:
        kind: PLANT_DRIFTLAB or PLANT_COMMONROAD_STD (the loop's kernel steps it with ``params`` and
            ``actuators``) or PLANT_EXTERNAL (the loop calls ``step`` each control step).
        params: the packed parameters of that step.
        actuators: actuator parameters (layout A_STEER_LAG ... A_DRIVE_RATE).
    """

    kind = PLANT_DRIFTLAB

    def __init__(self, config: PlantConfig, model_vehicle: VehicleParams) -> None:
        self.config = config
        self.vehicle = config.vehicle(model_vehicle)
        self.params = config.packed_params(model_vehicle)
        self.actuators = config.actuator_params()

    def start_state(self, loop_state: np.ndarray) -> np.ndarray:
        """The full state to start from, given the loop's eight (X_POS ... DRIVE); a plant with states of its own
        (wheel speeds, ...) appends them."""
        return loop_state.copy()

    def step(self, state: np.ndarray, steer_cmd_rad: float, drive_cmd_n: float, duration_s: float) -> np.ndarray:
        return plant_step(state, steer_cmd_rad, drive_cmd_n, duration_s, self.config.substep_s,
                          self.params, self.actuators)
