"""The report says so when the learned theta is no better than the untuned one; its rescore columns by phase."""

from driftlab.reports.job import _verdict


def _summary(j_mean, rate):
    return {"J_mean": j_mean, "completion_rate": rate}


def test_a_learned_theta_worse_than_the_untuned_one_gets_a_note():
    text = " ".join(_verdict(_summary(-0.2, 1.0), _summary(-0.5, 1.0), 30))
    assert "**Note:**" in text and "a worse J" in text and "30 evaluations" in text and "500" in text


def test_a_less_robust_learned_theta_gets_a_note_too():
    text = " ".join(_verdict(_summary(-0.9, 0.8), _summary(-0.5, 1.0), 500))
    assert "fewer completed episodes" in text and "a worse J" not in text


def test_a_better_learned_theta_is_said_to_be_better():
    text = " ".join(_verdict(_summary(-0.9, 1.0), _summary(-0.5, 1.0), 500))
    assert "beats the untuned one" in text and "lower is better" in text


def test_the_rescore_columns_show_the_drifts_and_the_flicks_beside_the_episodes_mean_error():
    from driftlab.reports.job import phase_cells

    summary = {"mean_abs_e_m": 0.92, "by_phase": {
        "drift": {"mean_abs_e_m": 0.81, "max_abs_e_m": 1.85, "rms_beta_err_rad": 0.0412, "episodes": 3},
        "flick": {"mean_abs_e_m": 1.234, "max_abs_e_m": 2.5, "rms_beta_err_rad": 0.2, "episodes": 3}}}
    assert phase_cells(summary) == "0.92 / 0.81 / 1.23 | 1.85 / 2.50 | 0.041 / 0.200"
    # A summary before by_phase existed, or one whose episodes all failed.
    assert phase_cells({"mean_abs_e_m": None}) == "- / - / - | - / - | - / -"


def test_the_rescore_column_counts_episodes_outside_the_plants_model_apart():
    from driftlab.reports.job import completed_cell

    assert completed_cell({"completed": 17, "samples": 20, "statuses": {"completed": 17, "invalid": 3}}) == \
        "17/20 (3 invalid)"
    assert completed_cell({"completed": 20, "samples": 20, "statuses": {"completed": 20}}) == "20/20"
