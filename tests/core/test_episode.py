"""Closed-loop episodes on the figure 8."""

import json
import math

import numpy as np
import pytest

from driftlab.core.config import PAPER_THETA, EpisodeConfig, ScenarioConfig, Theta
from driftlab.core.configure import apply_overrides, preset_config
from driftlab.core.episode import COL, failure_penalty, run_episode
from driftlab.core.errors import ConfigError
from driftlab.core.planner import Phase

NOMINAL = preset_config(plant="nominal", controller="paper")


@pytest.fixture(scope="module")
def nominal_run():
    return run_episode(Theta(c_lr=0.02, c_rl=0.02, dV=0.0, k=0.05), NOMINAL)


def test_nominal_plant_completes_the_eight(nominal_run):
    r = nominal_run
    assert r.status == "completed"
    assert r.metrics.completed_fraction == 1.0
    assert r.metrics.mean_abs_e_m < 0.3 and r.metrics.max_abs_e_m < 1.2
    assert r.metrics.mean_abs_beta_err_rad < 0.01
    assert len(r.trigger_points) == 2
    assert 27.0 < r.metrics.duration_s < 32.0
    assert math.isfinite(r.J) and r.J < 0.0


def test_beta_changes_sign_after_each_trigger(nominal_run):
    r = nominal_run
    t, beta = r.column("t_s"), r.column("beta_rad")
    for trig, sign_after in zip(r.trigger_points, (1.0, -1.0), strict=True):
        before = beta[t < trig["t_s"]][-1]
        after = beta[(t > trig["t_s"] + 1.5) & (t < trig["t_s"] + 3.0)]
        assert np.sign(before) == -sign_after
        assert np.all(np.sign(after) == sign_after)
    assert all(0.2 < f < 0.8 for f in r.metrics.beta_flip_s)


def test_the_phases_in_numbers_add_up_to_the_episode(nominal_run):
    """Per phase: the runs in the scenario's order, contiguous, each flick starting at its trigger and ending where
    the sideslip settled; the step-weighted means of |e| give the episode's mean |e|, the largest max its max."""
    r = nominal_run
    phases = r.metrics.phases
    assert json.loads(json.dumps(phases)) == phases  # stored as JSON with the evaluation
    assert [p["phase"] for p in phases] == ["left_drift", "inertia_left_to_right", "right_drift",
                                           "inertia_right_to_left", "left_drift_final"]
    assert all(a["end_s"] == b["start_s"] for a, b in zip(phases, phases[1:], strict=False))
    flicks = [p for p in phases if p["phase"].startswith("inertia")]
    for flick, trigger, flip, settle in zip(flicks, r.metrics.trigger_times_s, r.metrics.beta_flip_s,
                                            r.metrics.beta_settle_s, strict=True):
        assert flick["start_s"] == trigger and flick["end_s"] == pytest.approx(trigger + settle)
        assert flick["flip_s"] == flip and flick["settle_s"] == settle and 0.0 < flip < settle
        assert flick["speed_loss_mps"] >= 0.0 and flick["mean_abs_beta_err_rad"] > 0.1  # the sideslip crosses over
    beta, steer = r.column("beta_rad"), r.column("delta_rad")
    for p in phases:
        rows = (r.column("t_s") >= p["start_s"]) & (r.column("t_s") < p["end_s"]) & driving_rows(r)
        assert p["countersteer_share"] == pytest.approx(float(np.mean(beta[rows] * steer[rows] > 0.0)))
        assert p["rms_beta_err_rad"] >= p["mean_abs_beta_err_rad"] > 0.0
        assert "flip_s" in p if p["phase"].startswith("inertia") else "flip_s" not in p
    drifts = [p for p in phases if p["phase"].endswith("drift") or p["phase"].endswith("final")]
    assert all(p["countersteer_share"] > 0.9 for p in drifts)  # the nominal car drifts against the turn
    driving = r.column("phase") != Phase.FINISHED
    assert sum(p["steps"] for p in phases) == int(np.sum(driving))
    assert sum(p["steps"] * p["mean_abs_e_m"] for p in phases) == pytest.approx(
        float(np.sum(np.abs(r.column("e_m")[driving]))), rel=1e-12)
    assert max(p["max_abs_e_m"] for p in phases) == float(np.max(np.abs(r.column("e_m")[driving])))


def driving_rows(r):
    return r.column("phase") != Phase.FINISHED


def test_a_theta_whose_model_cannot_drift_is_refused_saying_why():
    from driftlab.core.episode import refusal_reason, runs

    std = preset_config("commonroad_std")
    r = run_episode(Theta(model_c_scale=0.85), std)
    assert r.status == "refused" and len(r.trajectory) == 0 and r.metrics.duration_s == 0.0
    assert "model_c_scale 0.85" in r.metrics.failure_reason and "no drift to hold" in r.metrics.failure_reason
    assert refusal_reason(Theta(model_c_scale=0.85), std) == r.metrics.failure_reason  # known before it runs
    assert not runs(std, {"model_c_scale": 0.85}) and runs(std, {"k": 0.05})
    assert run_episode(Theta(), std).metrics.failure_reason is None and refusal_reason(Theta(), std) is None


def test_the_optimizers_quick_check_answers_as_the_refusal_does_across_the_corrections_box():
    """``runs`` stops at the first start that finds each drift; ``refusal_reason`` solves them whole. On STD's BMW
    a part of the box has no drift (refused), the rest has one: the two agree on both, and on unequal radii."""
    from driftlab.core.episode import refusal_reason, runs

    for config in (preset_config("commonroad_std"),
                   apply_overrides(preset_config("commonroad_std"), {"scenario.right_radius_m": 30.0})):
        answers = []
        for mu in np.linspace(0.85, 1.2, 5):
            for c in np.linspace(0.85, 1.3, 6):
                theta = {"model_mu_scale": float(mu), "model_c_scale": float(c)}
                refused = refusal_reason(Theta.from_mapping(Theta.filled(theta)), config) is not None
                assert runs(config, theta) is not refused, theta
                answers.append(refused)
        assert 0 < sum(answers) < len(answers)


def test_path_stays_on_both_circles(nominal_run):
    phase = nominal_run.column("phase")
    assert {int(p) for p in phase} >= {Phase.LEFT_DRIFT, Phase.RIGHT_DRIFT, Phase.LEFT_DRIFT_FINAL}
    assert np.max(np.abs(nominal_run.column("e_m"))) < 1.2


def test_slow_steering_spins_out_with_a_worse_j(nominal_run):
    slow = run_episode(Theta(), apply_overrides(NOMINAL, {"mpc.steer_rate_radps": 0.6}))
    assert slow.status == "spun_out"
    assert slow.J > 3.31 > nominal_run.J
    assert slow.J == pytest.approx(failure_penalty(slow.metrics.completed_fraction))


@pytest.mark.parametrize("theta", [Theta(0.0, 0.0, 0.0, 0.0), PAPER_THETA])
def test_untuned_and_paper_theta_fail_on_nominal(theta):
    r = run_episode(theta, NOMINAL)
    assert r.status != "completed"
    assert 0.0 < r.metrics.completed_fraction < 0.5


def test_failure_penalty_orders_by_progress():
    assert failure_penalty(0.9) < failure_penalty(0.2)
    assert failure_penalty(1.0) > math.log(10 + 5 * math.pi + 1.6)


def test_a_diverging_config_is_a_result_not_an_exception():
    config = apply_overrides(NOMINAL, {"plant.friction_scale": 0.6})
    r = run_episode(Theta(), config)
    assert r.status in ("spun_out", "left_track", "gripped_up", "stalled", "diverged")
    assert math.isfinite(r.J)


# The best of 200 random theta in the default bounds on the default plant; BO finds better (J -1.78).
DEFAULT_PLANT_THETA = Theta(c_lr=0.0225, c_rl=0.0218, dV=-0.064, k=0.057)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_default_controller_drifts_the_eight_on_the_mismatched_plant(seed):
    r = run_episode(Theta(), EpisodeConfig(), seed=seed)  # the default plant varies by seed
    assert r.status == "completed"
    assert r.metrics.mean_abs_e_m <= 1.0 and r.metrics.max_abs_e_m <= 2.5
    beta = r.column("beta_rad")
    t = r.column("t_s")
    for trig, sign_after in zip(r.trigger_points, (1.0, -1.0), strict=True):
        after = beta[(t > trig["t_s"] + 1.5) & (t < trig["t_s"] + 3.0)]
        assert np.all(np.sign(after) == sign_after)


def test_paper_controller_fails_on_the_mismatched_plant():
    r = run_episode(DEFAULT_PLANT_THETA, preset_config(controller="paper"))
    assert r.status != "completed"


def test_three_laps_repeat_the_pattern_and_stay_on_the_path():
    one = run_episode(Theta(), EpisodeConfig(), seed=1)
    three = run_episode(Theta(), apply_overrides(EpisodeConfig(), {"scenario.laps": 3}), seed=1)
    assert three.status == "completed" and three.metrics.completed_fraction == 1.0
    assert [p["phase"] for p in three.trigger_points] == [Phase.INERTIA_LEFT_TO_RIGHT, Phase.INERTIA_RIGHT_TO_LEFT] * 3
    # the first lap is the one-lap episode's until that one finishes, its final half lap a left drift of the next
    n = len(one.trajectory) - 1
    first = one.trajectory[:n].copy()
    phase = first[:, COL["phase"]]
    phase[phase == Phase.LEFT_DRIFT_FINAL] = Phase.LEFT_DRIFT
    np.testing.assert_array_equal(three.trajectory[:n], first)
    laps = three.metrics.lap_mean_abs_e_m
    assert len(laps) == 3 and laps[2] <= 1.2 * laps[0]
    assert three.metrics.duration_s == pytest.approx(3 * one.metrics.duration_s, rel=0.05)
    assert one.metrics.lap_mean_abs_e_m == [one.metrics.mean_abs_e_m]


@pytest.mark.parametrize("laps", [0, 9, 1.5, True])
def test_laps_out_of_range_is_refused_naming_the_field(laps):
    with pytest.raises(ConfigError, match=r"scenario\.laps .*\[1, 8\]"):
        ScenarioConfig(laps=laps)
