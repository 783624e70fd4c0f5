"""The controller's model of a CommonRoad car, placed at the car's own steady drift.

PAC2002 with combined slip, wheel speeds and STD's load transfer gives a drift family the paper's simplified tyre
cannot reproduce with any (mu, B, C, front/rear grip split): vehicle 2 at R 44, beta -0.5 drifts at V 20.50 m/s,
delta -0.264 rad, drive 3636 N, where the model read off its tyre (mu 1.049, B 15.47, C 1.351) drifts at 21.86,
-0.361, 3520. Linearized about its own drift, the MPC steers toward the wrong place and the car spins out.
What a practitioner measures on a car is its steady drift; so the model keeps the car's mass, geometry and tyre
shape, and takes three numbers from that drift (the plant's drift family, driftlab.core.commonroad.equilibrium):
the friction that gives the drift speed, and a steering and a drive offset that put the equilibrium's inputs on
the car's (:class:`~driftlab.core.vehicle.VehicleParams` ``steer_offset_rad``, ``drive_offset_n``).
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache
from typing import Any

from scipy.optimize import brentq

from driftlab.core.commonroad.family import describe_family, drift_family
from driftlab.core.commonroad.parameters import commonroad_model_vehicle
from driftlab.core.commonroad.window import (
    FRONT_GRIP_LIMIT,
    FRONT_GRIP_STEP,
    CircleWindow,
    circle_window,
    elsewhere_text,
    no_drift_reason,
    range_text,
    widest_front_grip,
)
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.errors import ConfigError, NoEquilibriumError, OutsideDriftWindowError
from driftlab.core.results_cache import kept_on_disk
from driftlab.core.track import tiled_radii
from driftlab.core.vehicle import VehicleParams, pack_params


def _speed_gap(friction: float, base: VehicleParams, radius_m: float, sideslip_rad: float, target_mps: float):
    try:
        eq = drift_equilibrium(radius_m, -abs(sideslip_rad), pack_params(replace(base, friction=friction)))
    except NoEquilibriumError:
        return float("nan")
    return eq.speed_mps - target_mps


def fitted_model_vehicle(vehicle_id: int, radius_m: float, sideslip_rad: float,
                         model: Any, *, drive_coupling: bool = False) -> VehicleParams:
    """The model of CommonRoad vehicle ``vehicle_id`` whose drift at (radius, sideslip) is the car's main drift
    (``model``: the car's catalog entry, a driftlab.core.plants.CommonRoadPlantType; a multi-body car's model also
    answers the steering as strongly as the car does, its front grip, :func:`matched_front_grip`).

    Raises:
        OutsideDriftWindowError: the sideslip is outside the car's window on this circle (the error carries it).
        ConfigError: inside it, no friction of the model reaches the car's speed.

    ``drive_coupling``: the model takes the rear friction circle with the coupling at which its yaw rate answers a
    drive step from the drift as the car's does (:func:`matched_rear_coupling`).
    """
    return _fitted(vehicle_id, radius_m, sideslip_rad, model, drive_coupling)


@lru_cache(maxsize=64)
def _fitted(vehicle_id: int, radius_m: float, sideslip_rad: float, model: Any, drive_coupling: bool) -> VehicleParams:
    try:
        return _fit(vehicle_id, radius_m, sideslip_rad, model, drive_coupling)
    except ConfigError as exc:
        raise _refusal(exc, vehicle_id, radius_m, sideslip_rad, model, drive_coupling) from None


def check_fittable(vehicle_id: int, radius_m: float, sideslip_rad: float, model: Any) -> None:
    """Raise what :func:`fitted_model_vehicle` raises outside the car's window on this circle, without fitting: the
    car's main drift there must countersteer both ways, and the model read off its tyres (its front grip raised as
    far as a fit raises it) must have a drift there, the two windows of
    driftlab.core.commonroad.window.circle_window. ~0.1-0.3 s the
    first time (the car's drift family, cached), the fit itself 0.3-0.8 s. Inside the window a fit can still miss
    the car's drift speed; it raises then."""
    try:
        _main_drift(vehicle_id, radius_m, sideslip_rad, False, model)
        _main_drift(vehicle_id, radius_m, sideslip_rad, True, model)
        widest = pack_params(widest_front_grip(commonroad_model_vehicle(model.car(vehicle_id))))
        try:
            drift_equilibrium(radius_m, -abs(sideslip_rad), widest)
        except NoEquilibriumError as exc:
            raise ConfigError(f"the controller's model of {model.car_name(vehicle_id)} has no "
                              f"drift at radius {radius_m:g} m, sideslip {abs(sideslip_rad):g} rad: {exc}",
                              field="scenario.sideslip_rad") from None
    except ConfigError as exc:
        raise _refusal(exc, vehicle_id, radius_m, sideslip_rad, model) from None


def _refusal(exc: ConfigError, vehicle_id: int, radius_m: float, sideslip_rad: float, model: Any,
             drive_coupling: bool | None = None) -> ConfigError:
    """Why a fit at this drift fails, with where a job of this car can drift instead: the sideslips of this circle
    (never a range that holds the refused one), or, where it has none, why not and which other circles it drifts."""
    window, beta = circle_window(model, vehicle_id, radius_m), abs(sideslip_rad)
    job = window.job
    if job is not None and job[0] <= beta <= job[1]:  # inside the window, but this model has no fit: not its edge
        other = (" (plant.model_drive_coupling=false places the paper's rear model instead)" if drive_coupling
                 else "")
        return ConfigError(f"{exc}: {beta:g} rad is inside the sideslips {model.car_name(vehicle_id)} drifts at on "
                           f"a {radius_m:g} m circle, but this controller's model of it cannot be placed at its drift "
                           f"there{other}", field=exc.field)
    if job is None:
        elsewhere = elsewhere_text(model, vehicle_id, radius_m, tiled_radii(radius_m))
        message = f"{exc}. {no_drift_reason(model, vehicle_id, radius_m)}" + (f"; {elsewhere}" if elsewhere else "")
    else:
        message = f"{exc}. {windows_text(model, vehicle_id, window)}"
    return OutsideDriftWindowError(message, field=exc.field, window=job)


def windows_text(model: Any, vehicle_id: int, window: CircleWindow) -> str:
    """Where a job of this car on the window's circle can drift (:func:`circle_window`): a job needs both."""
    assert window.car is not None and window.model is not None and window.job is not None
    return (f"On a {window.radius_m:g} m circle (sideslips 0.20-0.80 rad scanned) {model.car_name(vehicle_id)} drifts "
            f"with countersteer both ways at {range_text(window.car)}, the controller's model of it at "
            f"{range_text(window.model)}: a job of this car on this circle needs a scenario.sideslip_rad in "
            f"{range_text(window.job)}")


@kept_on_disk  # 0.1-0.4 s, ~3 s with the drive coupling (~460 of the model's equilibria): once for all processes
def _fit(vehicle_id: int, radius_m: float, sideslip_rad: float, model: Any, drive_coupling: bool) -> VehicleParams:
    left = _main_drift(vehicle_id, radius_m, sideslip_rad, False, model)
    right = _main_drift(vehicle_id, radius_m, sideslip_rad, True, model)
    base = commonroad_model_vehicle(model.car(vehicle_id))
    if drive_coupling:
        base = replace(base, rear_friction_circle=True)
        base = replace(base, rear_coupling=matched_rear_coupling(base, vehicle_id, radius_m, left, right, model))
    elif model.multibody:
        # The multi-body car's rear wheels spin up under more drive and its rear slides further: the model takes
        # the drive's share of the rear grip, or it answers the drive with the opposite sign (VehicleParams).
        base = replace(base, rear_friction_circle=True)
        base = replace(base, front_grip_scale=matched_front_grip(base, vehicle_id, radius_m, left, right, model))
    return _placed_with_front_grip(base, radius_m, sideslip_rad, left, right)


def _placed_with_front_grip(base: VehicleParams, radius_m: float, sideslip_rad: float, left, right) -> VehicleParams:
    """``base`` placed at the car's drift; where it has no drift there, the same with its front grip raised step by
    step, the first that has. Above ~0.57 rad the read-off model's equilibrium needs its front tyre past its peak
    slip (whatever the friction), while the car (PAC2002 with load transfer and combined slip) still countersteers
    up to 0.8 rad: more front grip gives the model's front tyre the force the drift needs before its peak. Where
    the read-off model fits, it is kept as it is."""
    try:
        return _placed_at_drift(base, radius_m, sideslip_rad, left, right)
    except ConfigError as first:
        grip = base.front_grip_scale
        while grip + FRONT_GRIP_STEP <= FRONT_GRIP_LIMIT + 1e-9:
            grip = round(grip + FRONT_GRIP_STEP, 6)
            try:
                return _placed_at_drift(replace(base, front_grip_scale=grip), radius_m, sideslip_rad, left, right)
            except ConfigError:
                continue
        raise first from None


def matched_front_grip(base: VehicleParams, vehicle_id: int, radius_m: float, left, right, model: Any) -> float:
    """The front grip scale in [1, 3] at which the model's yaw rate answers a steering step from the drift as the
    car's does (driftlab.core.commonroad.steering_gain); 1 when the car answers more weakly than the model read
    off its tyre (STD's saturated front axle does). Each candidate is placed at the car's drift first."""
    from driftlab.core.commonroad.steering_gain import car_yaw_response, model_yaw_response

    car, steering, _ = car_yaw_response(model.build(model.preset(vehicle_id), VehicleParams()), left, radius_m)

    def gap(grip: float) -> float:
        vehicle = _placed_at_drift(replace(base, front_grip_scale=grip), radius_m, left.sideslip_rad, left, right)
        return model_yaw_response(vehicle, left, steering) - car

    if gap(1.0) >= 0.0:
        return 1.0
    if gap(3.0) <= 0.0:
        return 3.0
    return float(brentq(gap, 1.0, 3.0, xtol=1e-4))


def matched_rear_coupling(base: VehicleParams, vehicle_id: int, radius_m: float, left, right, model: Any) -> float:
    """The rear coupling in [0, 1] at which the model's yaw rate answers a drive step from the drift as the car's
    does (0: the paper's independent rear forces, 1: the whole friction circle); each candidate is placed at the
    car's drift first. STD's BMW at 44 m, +500 N: the car +0.020 to +0.025 rad/s, the paper's model -0.0005, the
    whole circle +0.037 to +0.044."""
    from driftlab.core.commonroad.steering_gain import DRIVE_STEP_N, car_yaw_response, model_yaw_response

    car, steering, drive = car_yaw_response(model.build(model.preset(vehicle_id), VehicleParams()), left, radius_m,
                                            steer_step_rad=0.0, drive_step_n=DRIVE_STEP_N)

    def gap(coupling: float) -> float:
        vehicle = _placed_at_drift(replace(base, rear_coupling=coupling), radius_m, left.sideslip_rad, left, right)
        return model_yaw_response(vehicle, left, steering, drive) - car

    if gap(0.0) >= 0.0:
        return 0.0
    if gap(1.0) <= 0.0:
        return 1.0
    return float(brentq(gap, 0.0, 1.0, xtol=1e-4))


def _placed_at_drift(base: VehicleParams, radius_m: float, sideslip_rad: float, left, right) -> VehicleParams:
    """``base`` with the friction that gives the car's drift speed and the offsets that put its equilibrium's
    inputs on the car's, both ways."""
    # The drift speed grows with friction (V^2 ~ mu g R): bracket it, then solve (on the left-hand drift; the
    # right-hand one of vehicle 2 is 0.1 m/s slower, within what dV corrects).
    lo, hi = 0.3 * base.friction, min(1.9 * base.friction, 2.0)
    grid = [lo + (hi - lo) * i / 40 for i in range(41)]
    gaps = [(f, _speed_gap(f, base, radius_m, sideslip_rad, left.speed_mps)) for f in grid]
    bracket = next(((a, b) for (a, ga), (b, gb) in zip(gaps[:-1], gaps[1:], strict=True)
                    if ga == ga and gb == gb and ga * gb <= 0), None)  # x == x: not NaN (no drift there)
    if bracket is None:
        raise ConfigError(f"no model friction in [{lo:.3g}, {hi:.3g}] drifts at the car's {left.speed_mps:.2f} m/s "
                          f"(radius {radius_m:g} m, sideslip {abs(sideslip_rad):g} rad)", field="scenario.sideslip_rad")
    friction = brentq(_speed_gap, *bracket, args=(base, radius_m, sideslip_rad, left.speed_mps), xtol=1e-12)
    fitted = replace(base, friction=float(friction))
    eq = drift_equilibrium(radius_m, -abs(sideslip_rad), pack_params(fitted))  # offsets 0: the same both ways
    mass = base.mass_kg
    # Right-hand offsets in the mirror image (left-hand form): its steering flips sign, its drive force stays.
    return replace(fitted, steer_offset_rad=float(eq.steer_rad - left.steer_rad),
                   drive_offset_n=float(eq.drive_force_n - mass * left.acceleration_mps2),
                   steer_offset_right_rad=float(eq.steer_rad + right.steer_rad),
                   drive_offset_right_n=float(eq.drive_force_n - mass * right.acceleration_mps2))


def _main_drift(vehicle_id: int, radius_m: float, sideslip_rad: float, right: bool, model: Any):
    family = drift_family(model, vehicle_id, radius_m, sideslip_rad, right)
    why = describe_family(family)
    if why is not None:
        side = "right" if right else "left"
        raise ConfigError(f"the controller's model cannot be fitted to {model.car_name(vehicle_id)} at radius "
                          f"{radius_m:g} m, sideslip {abs(sideslip_rad):g} rad ({side}-hand drift): {why}",
                          field="scenario.sideslip_rad")
    return family[0]
