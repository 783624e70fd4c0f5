"""An episode's outcome as one sample of a robust evaluation: its errors by phase group, from a real episode."""

import numpy as np
import pytest

from driftlab.core.config import Theta
from driftlab.core.planner import Phase
from driftlab.core.robust import PHASE_GROUPS, SampleResult
from driftlab.core.tuning import TuningSpec
from driftlab.worker.executors.episode import evaluate_episode


@pytest.fixture(scope="module")
def outcome():
    return evaluate_episode(Theta().as_dict(), TuningSpec().to_dict()["config"], seed=3)


def test_a_real_episodes_phase_errors_are_those_of_its_steps_in_the_drifts_and_the_flicks(outcome):
    assert outcome.completed, outcome.status
    sample = outcome.sample
    rows = outcome.trajectory
    column = {name: i for i, name in enumerate(outcome.columns)}
    phase = rows[:, column["phase"]].astype(int)
    e_m = rows[:, column["e_m"]]
    beta_err_rad = rows[:, column["beta_rad"]] - rows[:, column["beta_ref_rad"]]
    for group, phases in PHASE_GROUPS.items():
        steps = np.isin(phase, [int(p) for p in phases])
        error = sample.phase_error(group)
        assert steps.sum() > 0 and error is not None, group
        # Step-weighted: straight from the trajectory's steps in the group, the phase segments never looked at.
        assert error.mean_abs_e_m == pytest.approx(np.mean(np.abs(e_m[steps])), rel=1e-9), group
        assert error.max_abs_e_m == pytest.approx(np.max(np.abs(e_m[steps])), rel=1e-12), group
        assert error.rms_beta_err_rad == pytest.approx(np.sqrt(np.mean(beta_err_rad[steps] ** 2)), rel=1e-9), group
        # and consistent with the episode's own phase segments (metrics.phases).
        segments = [p for p in outcome.metrics["phases"] if Phase[p["phase"].upper()] in phases]
        assert sum(p["steps"] for p in segments) == steps.sum(), group
        assert error.max_abs_e_m == max(p["max_abs_e_m"] for p in segments), group
        assert min(p["mean_abs_e_m"] for p in segments) <= error.mean_abs_e_m <= max(
            p["mean_abs_e_m"] for p in segments), group
    # The default scenario flicks twice: both inertia phases are there, and they are what "flick" covers.
    assert {p["phase"] for p in outcome.metrics["phases"]} >= {"inertia_left_to_right", "inertia_right_to_left"}
    assert sample.drift.max_abs_e_m <= outcome.metrics["max_abs_e_m"]
    assert SampleResult.from_dict(sample.as_dict()) == sample

