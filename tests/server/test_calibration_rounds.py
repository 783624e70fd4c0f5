"""A calibration's rounds (driftlab.core.calibration_run) on a real SQLite file, with scripted episodes: a point
where nothing completes with the untuned theta gets one round more, each round after the first searches around the
last one's weights when they completed something, and every round is a stored profile."""

import pytest

from driftlab.core.calibration_request import CalibrationRequest
from driftlab.db import profiles, storage
from driftlab.services.calibration import run_calibration

FAILED = ("spun_out", 8.0, 0.5, None)
COMPLETED = ("completed", -1.0, 1.0, 0.3)


@pytest.fixture
def factory(tmp_path):
    factory = storage.open_database(f"sqlite:///{tmp_path / 'rounds.db'}")
    yield factory
    storage.close_database(factory)


def _run(factory, outcome, **request):
    events = []
    documents = run_calibration(
        CalibrationRequest(plant="commonroad_std", points="0.5@44", iterations=2, seeds=1,
                           sets={"plant.model_drive_coupling": False}, **request),
        factory, lambda batch: [outcome] * len(batch), on_event=events.append)
    return documents, events


def test_a_point_where_nothing_completes_gets_a_round_that_learns_a_theta(factory):
    documents, events = _run(factory, FAILED)
    assert [d["round"] for d in documents] == [1, 2]
    assert documents[0]["theta"] == "untuned" and documents[1]["theta"] != "untuned"
    assert any("one more round learns the theta" in e.get("message", "") for e in events)
    assert [e["progress"]["step"] for e in events if "progress" in e][-1] == "weights"
    with storage.snapshot(factory) as session:
        assert [p.id for p in profiles.list_profiles(session)] == [d["profile_id"] for d in documents]


def test_a_point_that_completes_stops_after_the_rounds_asked_for(factory):
    documents, _ = _run(factory, COMPLETED)
    assert [d["round"] for d in documents] == [1]
    documents, _ = _run(factory, COMPLETED, rounds=2)
    first, second = documents
    assert second["round"] == 2 and second["start"]["weights"] == pytest.approx(first["weights"], rel=1e-9)
    documents, _ = _run(factory, FAILED, rounds=1, theta={"dV": 0.1})  # a theta given: searched for it only
    assert [d["round"] for d in documents] == [1]
