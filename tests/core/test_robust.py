"""Robust evaluation's aggregate and seeds."""

import dataclasses

import pytest

from driftlab.core.episode import failure_penalty
from driftlab.core.robust import RESCORE_SEED_BASE, SampleResult, aggregate, rescore_seeds, summarize, tuning_seeds
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
    reported = SampleResult(3, "completed", -1.5, 1.0, 0.12, 0.25, 0.0)
    assert reported.as_dict() == dataclasses.asdict(reported)
    silent = SampleResult(4, "spun_out", 7.0, 0.4)
    assert silent.as_dict() == {k: v for k, v in dataclasses.asdict(silent).items()
                                if k not in ("negative_wheel_load_s", "one_side_off_s")}
