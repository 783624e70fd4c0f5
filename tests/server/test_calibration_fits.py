"""A candidate controller model that cannot be fitted at a point (driftlab.core.calibration_run): the workers fit
each point's model with its first episode, so the episodes here are scripted but fitted as a worker fits them."""

import pytest

from driftlab.core.calibration_request import CalibrationRequest
from driftlab.core.configure import config_from_dict, fitted
from driftlab.core.errors import ConfigError
from driftlab.db import storage
from driftlab.services.calibration import run_calibration

COMPLETED = ("completed", -1.0, 1.0, 0.3)
# The VW Vanagon at 0.69 rad, 44 m: inside its window (0.57-0.80 rad), where the paper's rear model fits its drift
# and the coupled rear model (plant.model_drive_coupling) does not (no friction of it reaches the car's speed).
VANAGON = {"plant.commonroad_vehicle": 3, "mpc.steer_limit_rad": 0.6}


@pytest.fixture
def factory(tmp_path):
    factory = storage.open_database(f"sqlite:///{tmp_path / 'fits.db'}")
    yield factory
    storage.close_database(factory)


def _fitting_batch(batch):
    """What a worker does before each episode (driftlab.worker.executors.episode): parse and fit the config."""
    for _, document, _ in batch:
        fitted(config_from_dict(document))
    return [COMPLETED] * len(batch)


def test_a_candidate_model_without_a_fit_at_a_point_is_skipped_there_with_one_line(factory):
    events = []
    documents = run_calibration(CalibrationRequest(plant="commonroad_std", sets=VANAGON, points="0.69@44",
                                                   iterations=1, seeds=1),
                                factory, _fitting_batch, on_event=events.append)
    messages = [e["message"] for e in events if "message" in e]
    skipped = [m for m in messages if m.startswith("skipped the model with plant.model_drive_coupling=true")]
    assert len(skipped) == 1 and "0.69 rad @ R 44 m" in skipped[0] and "no model friction" in skipped[0], messages
    document, = documents
    assert document["plant"]["model_drive_coupling"] is False and document["completed"] == 1
    assert [c["model_drive_coupling"] for c in document["candidates"]] == [False]
    unfitted, = document["unfitted_candidates"]
    assert unfitted["model_drive_coupling"] is True and unfitted["skipped"][0]["sideslip_rad"] == 0.69


def test_a_calibration_fails_only_where_no_candidate_fits_at_any_point(factory, monkeypatch):
    """Every fit fails (the worker's and the calibration's own look at which point failed): each candidate is
    skipped at each point with the reason, then the calibration fails, naming them."""
    import driftlab.core.calibration as core_calibration

    def no_fit(config):
        raise ConfigError(f"no fit at {config.scenario.sideslip_rad:g} rad", field="scenario.sideslip_rad")

    def failing_batch(batch):
        for _, document, _ in batch:
            no_fit(config_from_dict(document))
        return [COMPLETED] * len(batch)

    monkeypatch.setattr(core_calibration, "fitted", no_fit)
    events = []
    request = CalibrationRequest(plant="commonroad_std", sets=VANAGON, points="0.65@44,0.69@44", iterations=1,
                                 seeds=1)
    with pytest.raises(ConfigError, match="no candidate model .* can be fitted") as failed:
        run_calibration(request, factory, failing_batch, on_event=events.append)
    assert "0.65 rad @ R 44 m: no fit at 0.65 rad" in str(failed.value) and "0.69 rad" in str(failed.value)
    skipped = [e["message"] for e in events if e.get("message", "").startswith("skipped the model with")]
    assert len(skipped) == 2 * 2  # both rear models at both points
    assert sum(e.get("message", "").startswith("skipped 0.") for e in events) == 2  # each point said once
