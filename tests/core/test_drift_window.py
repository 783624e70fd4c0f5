"""The drift window per circle, both ways, and why a circle has none (driftlab.core.drivability.drift_window,
driftlab.core.commonroad.window): a BMW 320i registered as docs/calibration.md shows (15% lighter, 10% less yaw
inertia, 10% grippier tyres, its CoG 10% higher) has no drift on 44 m because its engine gives too little at drift
speed, and drifts on 40 m only where its right-hand drift exists too."""

import json
import re

import pytest

from driftlab.core.configure import apply_overrides, fitted, preset_config
from driftlab.core.drivability import drift_window
from driftlab.core.errors import ConfigError, OutsideDriftWindowError
from driftlab.core.plants import CommonRoadVariant, plant_type, register_plant

LIGHT = {"m": 0.85, "I_z": 0.9, "tire.p_dx1": 1.1, "tire.p_dy1": 1.1, "h_s": 1.1, "h_cg": 1.1}


@pytest.fixture(scope="module")
def light_bmw():
    if plant_type("light_bmw_test") is None:
        register_plant("light_bmw_test", CommonRoadVariant(LIGHT))
        register_plant("light_bmw_engine_test", CommonRoadVariant({**LIGHT, "longitudinal.a_max": 1 / 0.85}))
    return apply_overrides(preset_config("commonroad_std"), {"plant.model": "light_bmw_test"})


def test_a_circle_without_a_drift_says_the_engine_is_short_and_where_the_car_drifts(light_bmw):
    window = drift_window(light_bmw, 44.0, 0.55, 0.65)
    assert window.ranges_rad == [] and window.reason is not None
    reason = window.reason
    assert reason.startswith("light_bmw_test (CommonRoad's BMW 320i, scaled) has no steady drift"), reason
    assert "CommonRoad vehicle 2" not in reason and "no sideslip" not in reason
    assert "needs more rear drive than CommonRoad's engine gives" in reason and "unlimited drive" not in reason
    shortfall = re.search(r"needs (\d\.\d\d) m/s\^2 .* gives (\d\.\d\d) m/s\^2", reason)
    needed, given = (float(x) for x in shortfall.groups())
    assert needed > given  # the shortfall, in the engine's own terms
    assert re.search(r"it drifts on a 30 m circle at 0\.\d\d-0\.80 rad", reason), reason
    # The same car with its engine kept (a_max is an acceleration: scaling the mass scaled the engine's force).
    kept = apply_overrides(light_bmw, {"plant.model": "light_bmw_engine_test"})
    assert drift_window(kept, 44.0, 0.55, 0.65).ranges_rad == [(0.55, 0.65)]


def test_a_circle_without_a_drift_whatever_the_drive_says_the_tyres():
    """A BMW whose rear tyres grip 2.5 times as hard along the road has no countersteer drift on 44 m even with the
    engine's cap lifted: the tyres, not the engine."""
    from driftlab.core.commonroad.window import drive_shortfall, no_drift_reason

    if plant_type("grippy_rear_test") is None:
        register_plant("grippy_rear_test", CommonRoadVariant({"tire.p_dx1": 2.5}))
    entry = plant_type("grippy_rear_test")
    assert drive_shortfall(entry, 2, 44.0) is None
    reason = no_drift_reason(entry, 2, 44.0)
    assert reason.startswith("grippy_rear_test (CommonRoad's BMW 320i, scaled) has no steady drift"), reason
    assert "even with unlimited drive: its tyres hold no countersteer equilibrium there" in reason
    assert "engine" not in reason


def test_the_window_of_a_circle_is_where_both_its_drifts_exist(light_bmw):
    """On 40 m the light car's left-hand drift countersteers from 0.51 rad, its right-hand one from 0.60: a job is
    refused below 0.60 (both circles of the 8), and the window says so."""
    (low, high), = drift_window(light_bmw, 40.0, 0.5, 0.62).ranges_rad
    assert (low, high) == (0.6, 0.62)
    at_40 = {"scenario.left_radius_m": 40.0, "scenario.right_radius_m": 40.0}
    with pytest.raises(OutsideDriftWindowError) as refused:
        fitted(apply_overrides(light_bmw, {**at_40, "scenario.sideslip_rad": 0.55}))
    message = str(refused.value)
    assert "light_bmw_test (CommonRoad's BMW 320i, scaled)" in message and "right-hand drift" in message
    assert "needs a scenario.sideslip_rad in 0.60-0.80 rad" in message and refused.value.window == (0.6, 0.8)


def test_a_sideslip_inside_the_window_without_a_fit_of_the_model_names_no_range_that_holds_it():
    """The VW Vanagon at 0.69 rad, 44 m drifts both ways; its coupled rear model has no friction reaching its speed."""
    config = apply_overrides(preset_config("commonroad_std"),
                             {"plant.commonroad_vehicle": 3, "scenario.sideslip_rad": 0.69,
                              "plant.model_drive_coupling": True})
    with pytest.raises(ConfigError) as refused:
        fitted(config)
    message = str(refused.value)
    assert not isinstance(refused.value, OutsideDriftWindowError)
    assert "needs a scenario.sideslip_rad" not in message and "0.69 rad is inside" in message
    assert "CommonRoad vehicle 3 (VW Vanagon)" in message and "plant.model_drive_coupling=false" in message


def test_the_window_command_prints_a_line_a_radius_and_the_reason_where_there_is_none(light_bmw, capsys):
    from driftlab.cli import main

    assert main(["equilibrium", "--window", "--plant", "commonroad_std", "--set", "plant.model=light_bmw_test",
                 "--radius", "44", "--radius", "40"]) == 0
    out = capsys.readouterr().out
    lines = out.strip().splitlines()
    assert len(lines) == 4  # the brackets and one line a radius
    at_40, at_44 = (json.loads(line.rstrip(",")) for line in lines[1:3])
    assert at_40 == {"radius_m": 40.0, "sideslip_ranges_rad": [[0.6, 0.8]]}
    assert at_44["radius_m"] == 44.0 and at_44["sideslip_ranges_rad"] == [] and "engine" in at_44["reason"]
    assert json.loads(out)["window"] == [at_40, at_44]
