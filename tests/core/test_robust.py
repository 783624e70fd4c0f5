"""Robust evaluation's aggregate and seeds."""

import dataclasses
import math

import pytest

from driftlab.core.episode import failure_penalty
from driftlab.core.robust import (
    PHASE_GROUPS,
    RESCORE_SEED_BASE,
    PhaseError,
    SampleResult,
    aggregate,
    phase_errors,
    rescore_seeds,
    summarize,
    tuning_seeds,
)
from driftlab.core.tuning import TuningSpec


def _s(seed, status, value, fraction=1.0):
    return SampleResult(seed, status, value, fraction)


def test_all_completed_is_the_mean_and_keeps_the_worst_trajectory():
    score = aggregate([_s(0, "completed", -1.0), _s(1, "completed", -0.4), _s(2, "completed", -1.3)])
    assert score.status == "completed" and score.n_completed == 3
    assert score.J == pytest.approx(-0.9)
    assert score.representative == 1


def test_one_failed_episode_fails_the_evaluation_and_its_penalty_enters_the_mean():
    penalty = failure_penalty(0.6)
    score = aggregate([_s(0, "completed", -1.0), _s(1, "gripped_up", penalty, 0.6), _s(2, "completed", -1.0)])
    assert score.status == "gripped_up" and score.n_completed == 2
    assert score.J == pytest.approx((penalty - 2.0) / 3)
    assert score.representative == 1


def test_tuning_seeds_are_common_to_a_job_and_rescore_seeds_never_overlap_them():
    assert tuning_seeds(0, 3) == [0, 1, 2]
    spec = TuningSpec(seed=2, robust_samples=2, confirm_samples=3)
    assert spec.episode_seeds == [128, 129] and spec.confirm_seeds == [130, 131, 132]
    largest = max(tuning_seeds(2**31 - 1, 64))
    assert largest < RESCORE_SEED_BASE == min(rescore_seeds(5))


def test_summary_counts_completion_and_tail():
    out = summarize([_s(0, "completed", -1.0), _s(1, "spun_out", 5.0, 0.4), _s(2, "completed", -0.5),
                     _s(3, "completed", -1.5)])
    assert out["completed"] == 3 and out["completion_rate"] == 0.75
    assert out["J_worst"] == 5.0 and out["J_mean"] == pytest.approx(0.5)
    assert out["J_mean_completed"] == pytest.approx(-1.0) and out["statuses"] == {"completed": 3, "spun_out": 1}


@pytest.mark.parametrize("value", [0, 65, True, 2.0])
def test_robust_samples_out_of_range_names_the_field(value):
    from driftlab.core.errors import ConfigError

    with pytest.raises(ConfigError, match=r"robust_samples must be an integer in \[1, 64\]"):
        TuningSpec(robust_samples=value)


def test_confirm_samples_share_the_seed_block():
    from driftlab.core.errors import ConfigError

    with pytest.raises(ConfigError, match=r"confirm_samples must be an integer in \[0, 4\]"):
        TuningSpec(robust_samples=60, confirm_samples=5)


def test_a_plants_validity_is_summed_over_the_samples_that_report_it():
    from driftlab.core.robust import SampleResult, summarize

    plain = [SampleResult(s, "completed", -1.0, 1.0, 0.2) for s in range(3)]
    assert "negative_wheel_load" not in summarize(plain)
    assert "negative_wheel_load_s" not in plain[0].as_dict()  # stored as before
    mb = [SampleResult(0, "completed", -1.0, 1.0, 0.2, 0.0), SampleResult(1, "spun_out", 8.0, 0.5, 1.0, 0.35),
          SampleResult(2, "completed", -0.5, 1.0, 0.3, 0.1)]
    assert summarize(mb)["negative_wheel_load"] == {"episodes": 2, "of": 3, "mean_s": pytest.approx(0.15),
                                                    "max_s": 0.35}
    assert SampleResult(**mb[1].as_dict()) == mb[1]
    assert "one_side_off" not in summarize(mb)  # stored before lift-off: not reported
    lifting = [SampleResult(0, "completed", -1.0, 1.0, 0.2, 0.3, 0.0), SampleResult(1, "invalid", 8.0, 0.1, 1.0, 0.4,
                                                                                     0.25)]
    summary = summarize(lifting)
    assert summary["one_side_off"] == {"episodes": 1, "of": 2, "mean_s": pytest.approx(0.125), "max_s": 0.25}
    assert summary["statuses"] == {"completed": 1, "invalid": 1} and summary["completed"] == 1


def test_a_sample_is_stored_with_every_field_and_without_a_wheel_load_it_did_not_report():
    reported = SampleResult(3, "completed", -1.5, 1.0, 0.12, 0.25, 0.0, drift=PhaseError(0.1, 0.3, 0.02),
                            flick=PhaseError(0.2, 0.5, 0.07))
    fields = dataclasses.asdict(reported)
    assert reported.as_dict() == {**{k: v for k, v in fields.items() if k not in PHASE_GROUPS},
                                  "by_phase": {group: fields[group] for group in PHASE_GROUPS}}
    assert SampleResult.from_dict(reported.as_dict()) == reported
    silent = SampleResult(4, "spun_out", 7.0, 0.4)
    assert silent.as_dict() == {k: v for k, v in dataclasses.asdict(silent).items()
                                if k not in ("negative_wheel_load_s", "one_side_off_s", *PHASE_GROUPS)}


def _phased(seed, status, drift, flick, value=-1.0):
    return SampleResult(seed, status, value, 1.0 if status == "completed" else 0.5, 0.5,
                        drift=None if drift is None else PhaseError(*drift),
                        flick=None if flick is None else PhaseError(*flick))


def test_by_phase_averages_the_completed_episodes_and_keeps_their_largest_error():
    samples = [_phased(0, "completed", (0.2, 0.8, 0.03), (0.6, 1.5, 0.12)),
               _phased(1, "completed", (0.4, 1.2, 0.04), (1.0, 1.9, 0.09)),
               _phased(2, "completed", (0.3, 0.9, 0.00), None),  # a run that never flicked
               _phased(3, "left_track", (5.0, 9.0, 0.9), (4.0, 8.0, 0.8), value=7.0)]  # ignored: it failed
    by_phase = summarize(samples)["by_phase"]
    assert by_phase["drift"] == {"mean_abs_e_m": pytest.approx(0.3), "max_abs_e_m": 1.2,
                                 "rms_beta_err_rad": pytest.approx(math.sqrt((0.03**2 + 0.04**2) / 3)), "episodes": 3}
    assert by_phase["flick"] == {"mean_abs_e_m": pytest.approx(0.8), "max_abs_e_m": 1.9,
                                 "rms_beta_err_rad": pytest.approx(math.sqrt((0.12**2 + 0.09**2) / 2)), "episodes": 2}
    assert summarize([_phased(0, "completed", None, None), samples[3]])["by_phase"] == {}


def _segment(phase, steps, mean_abs_e_m, max_abs_e_m, rms_beta_err_rad):
    """The fields of a phase segment (driftlab.core.metrics.phase_segments) that the groups read."""
    return {"phase": phase, "steps": steps, "mean_abs_e_m": mean_abs_e_m, "max_abs_e_m": max_abs_e_m,
            "rms_beta_err_rad": rms_beta_err_rad}


def test_a_groups_errors_weigh_each_step_the_same():
    segments = [_segment("left_drift", 300, 0.1, 0.4, 0.02), _segment("inertia_left_to_right", 50, 1.2, 2.0, 0.3),
                _segment("right_drift", 100, 0.5, 1.9, 0.06), _segment("inertia_right_to_left", 150, 0.4, 0.9, 0.1)]
    errors = phase_errors(segments)
    assert errors["drift"].mean_abs_e_m == pytest.approx((300 * 0.1 + 100 * 0.5) / 400)  # 0.2, not 0.3 (by phase)
    assert errors["drift"].max_abs_e_m == 1.9
    assert errors["drift"].rms_beta_err_rad == pytest.approx(math.sqrt((300 * 0.02**2 + 100 * 0.06**2) / 400))
    assert errors["flick"].mean_abs_e_m == pytest.approx((50 * 1.2 + 150 * 0.4) / 200)
    assert errors["flick"].max_abs_e_m == 2.0
    assert phase_errors(segments[:1]).keys() == {"drift"}  # stopped before its first flick
    diverged = [{**segments[0], "mean_abs_e_m": math.nan}]
    assert phase_errors(diverged) == {} and phase_errors([]) == {}


def test_a_sample_stored_before_phases_were_measured_reads_and_summarizes():
    old = {"seed": 7, "status": "completed", "J": -1.2, "completed_fraction": 1.0, "mean_abs_e_m": 0.3}
    sample = SampleResult.from_dict(old)
    assert sample.drift is None and sample.flick is None and sample.as_dict() == old
    new = _phased(8, "completed", (0.2, 0.7, 0.05), (0.9, 1.4, 0.1))
    out = summarize([sample, SampleResult.from_dict(new.as_dict())])
    assert out["completed"] == 2 and out["mean_abs_e_m"] == pytest.approx(0.4)
    assert out["by_phase"]["drift"]["episodes"] == 1 and out["by_phase"]["flick"]["max_abs_e_m"] == 1.4
