"""The report says so when the learned theta is no better than the untuned one."""

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
