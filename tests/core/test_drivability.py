"""A configuration without a drift at the scenario's radius and sideslip is refused before any episode runs."""

import pytest

from driftlab.core.config import EpisodeConfig
from driftlab.core.configure import apply_overrides, preset_config
from driftlab.core.drivability import NotDrivableError, check_drivable, drift_window, drivable_reason
from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.errors import ConfigError, NoEquilibriumError
from driftlab.core.vehicle import pack_params


def test_the_presets_are_drivable():
    assert drivable_reason(EpisodeConfig()) is None
    assert drivable_reason(preset_config(plant="nominal", controller="paper")) is None


@pytest.mark.parametrize("change", [{"plant.friction_scale": 1.15}, {"plant.tyre_c_scale": 1.0},
                                    {"plant.cg_height_m": 0.6}])
def test_default_plant_changes_without_a_drift_are_refused_naming_the_plant(change):
    config = apply_overrides(EpisodeConfig(), change)
    with pytest.raises(NotDrivableError) as info:
        check_drivable(config)
    message = str(info.value)
    assert "the plant" in message and "left circle" in message and "44 m" in message and "0.4 rad" in message
    assert isinstance(info.value, ConfigError)  # the API answers 422, the CLI exits 2
    # The reason is true: the plant itself has no drift there, while the controller's model has one.
    with pytest.raises(NoEquilibriumError):
        drift_equilibrium(44.0, -0.4, config.plant.packed_params(config.vehicle))
    assert drift_equilibrium(44.0, -0.4, pack_params(config.vehicle)).speed_mps == pytest.approx(19.1, rel=5e-3)


def test_each_circle_of_unequal_radii_is_checked():
    config = apply_overrides(EpisodeConfig(), {"scenario.right_radius_m": 60.0})
    assert "right circle" in drivable_reason(config) and "60 m" in drivable_reason(config)
    nominal = apply_overrides(preset_config("nominal"), {"scenario.left_radius_m": 30.0,
                                                                 "scenario.right_radius_m": 60.0})
    assert drivable_reason(nominal) is None


def test_the_drift_window_is_where_the_drivability_check_accepts_a_sideslip():
    config = EpisodeConfig()
    at_44 = drift_window(config, 44.0, 0.25, 0.55)
    (low, high), = at_44.ranges_rad  # one run of drivable sideslips
    assert 0.3 < low < 0.4 < high < 0.5
    for beta, inside in ((low, True), (high, True), (round(low - 0.01, 2), False), (round(high + 0.01, 2), False)):
        scenario = {"scenario.sideslip_rad": beta}
        assert (drivable_reason(apply_overrides(config, scenario)) is None) is inside
    (low_25, high_25), = drift_window(config, 25.0, 0.2, 0.6).ranges_rad
    assert low_25 < low and high_25 > high  # a tighter circle drifts over a wider range of sideslips
    assert drift_window(config, 60.0, 0.3, 0.5).ranges_rad == []
