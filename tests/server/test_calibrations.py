"""Calibration through the API, as `driftlab calibrate` runs it: queued, run by the job runner on its share of the
workers with real episodes, followed (progress, messages, profiles), cancelled; its profiles readable and taken by
the next job of that car."""

from concurrent.futures import ThreadPoolExecutor

import pytest

from driftlab.core.calibration import VERIFY_SEEDS
from driftlab.db import lease, storage
from driftlab.db.models import Calibration
from driftlab.worker.calibrating import run_stored_calibration
from driftlab.worker.slots import EpisodeSlots
from tests.server.conftest import InThreadExecutor

CAR = {"plant": "commonroad_std", "points": "0.5@44", "iterations": 2, "seeds": 1,
       "config": {"plant.model_drive_coupling": False}}


def _run_queued(api, executor):
    """What the server's runner does with the next queued calibration (driftlab.worker.job_runner)."""
    factory = api.app.state.factory
    with storage.transaction(factory) as session:
        calibration_id = lease.next_claimable(session, Calibration)
        assert lease.claim(session, Calibration, row_id=calibration_id, runner="test-runner")
    return run_stored_calibration(factory, calibration_id, executor, runner="test-runner", slots=EpisodeSlots(1),
                                  owner=("calibration", calibration_id))


@pytest.mark.parametrize(("change", "field"), [({"iterations": 0}, "iterations"), ({"seeds": 65}, "seeds"),
                                                ({"rounds": 2, "one_set": True}, "rounds"),
                                                ({"points": "0.5/44"}, "points"), ({"points": "0@0"}, "points"),
                                                ({"plant": "nope"}, "plant"), ({"theta": {"k": False}}, "k"),
                                                ({"theta": {"nope": 1.0}}, "nope"),
                                                ({"prune": {"confidence": 2.0}}, "confidence"),
                                                ({"prune": {"min_seeds": 1}}, "min_seeds"),
                                                ({"config": {"plant.mass_scale": "1.1"}}, "plant.mass_scale"),
                                                ({"iterations": 5000, "seeds": 64, "rounds": 3},
                                                 "DRIFTLAB_MAX_EPISODES_PER_STUDY"),
                                                ({"points": "0.5@44,0.55@44", "iterations": 5000, "seeds": 64},
                                                 "2 points x 1 rounds")])
def test_a_bad_calibration_request_names_its_field_and_stores_nothing(api, change, field):
    r = api.post("/api/calibrations", json={**CAR, **change})
    assert r.status_code == 422 and field in r.text, r.text
    assert api.get("/api/calibrations").json() == []


def test_a_calibration_runs_reports_its_progress_and_its_profile_drives_the_next_job(api):
    queued = api.post("/api/calibrations", json=CAR)
    assert queued.status_code == 202 and queued.json()["status"] == "queued", queued.text
    busy = api.post("/api/calibrations", json=CAR)
    assert busy.status_code == 409 and "DELETE /api/calibrations/" in busy.json()["detail"]
    with ThreadPoolExecutor(1) as pool:
        executor = InThreadExecutor(pool)
        assert _run_queued(api, executor) == "finished"
    # Two weight sets on one point and seed for each steering limit: the controller's 0.6 rad and the car's whole
    # 1.066 rad (the model was chosen); then the chosen weights on VERIFY_SEEDS fresh seeds at the point and half a
    # step either side of it.
    assert executor.submitted == 4 + 3 * VERIFY_SEEDS
    state = api.get(f"/api/calibrations/{queued.json()['id']}").json()
    assert state["status"] == "finished" and state["error"] is None, state
    # The two candidates' searches side by side, reported as one: 2 weight sets each.
    assert state["progress"]["tried"] == 4 and state["progress"]["of"] == 4 and state["progress"]["step"] == "weights"
    assert state["progress"]["candidates"] == 2
    assert any(m.startswith("calibrating 0.5 rad @ R 44 m") for m in state["messages"])
    profile_id, = state["profile_ids"]
    summary, = api.get("/api/profiles").json()
    assert summary["id"] == profile_id and summary["command"].startswith("POST /api/calibrations")
    document = api.get(f"/api/profiles/{profile_id}")
    assert document.status_code == 200 and "attachment" in document.headers["content-disposition"]
    assert document.json()["per_point"][0]["episodes"] == 1 and document.json()["iterations"] == 2
    verified = document.json()["per_point"][0]["verified"]
    assert verified["seeds"] == VERIFY_SEEDS and 0 <= verified["completed"] <= VERIFY_SEEDS
    around = document.json()["per_point"][0]["verified_around"]
    assert [a["sideslip_rad"] for a in around] == [0.475, 0.525] and all(a["seeds"] == VERIFY_SEEDS for a in around)
    assert any(m.startswith(f"checked on {VERIFY_SEEDS} fresh seeds: 0.475 rad @ R 44 m") for m in state["messages"])
    assert state["messages"][-1].startswith("calibrated window") and "R 44 m: " in state["messages"][-1]
    candidates = document.json()["candidates"]
    assert sorted(c["steer_limit_rad"] for c in candidates) == [0.6, 1.066]
    assert document.json()["mpc"]["steer_limit_rad"] == min(
        candidates, key=lambda c: (c["score"], -c["completed"]))["steer_limit_rad"]
    if verified["completed"]:  # its weights drove the point's fresh seeds: a job there takes them
        job = api.post("/api/jobs", json={"iterations": 1, "config": {"plant.model": "commonroad_std",
                                                                          "scenario.sideslip_rad": 0.5}}).json()
        assert job["profile_id"] == profile_id
        mpc = job["spec"]["config"]["mpc"]
        assert all(mpc[k] == v for k, v in document.json()["weights"].items())
        assert mpc["steer_limit_rad"] == document.json()["mpc"]["steer_limit_rad"]  # the limit they were found with
    assert api.get("/api/profiles/999").status_code == 404
    assert api.get("/api/calibrations/999").status_code == 404


def test_a_cancelled_calibration_stops_at_its_next_episode_and_keeps_what_it_stored(api):
    calibration_id = api.post("/api/calibrations", json={**CAR, "iterations": 50}).json()["id"]

    class CancelsAfterThree(InThreadExecutor):
        def submit(self, theta, config_doc, seed=0):
            if self.submitted == 3:
                assert api.delete(f"/api/calibrations/{calibration_id}").json()["status"] == "cancelled"
            return super().submit(theta, config_doc, seed)

    with ThreadPoolExecutor(1) as pool:
        executor = CancelsAfterThree(pool)
        assert _run_queued(api, executor) == "cancelled"
    # It stopped after the weight sets in flight (one for each of the 2 candidate models' searches, which run side by
    # side), not after 50 sets each.
    assert executor.submitted <= 3 + 2
    state = api.get(f"/api/calibrations/{calibration_id}").json()
    assert state["status"] == "cancelled" and state["profile_ids"] == []
    assert api.delete(f"/api/calibrations/{calibration_id}").status_code == 404  # nothing left to cancel
    with storage.snapshot(api.app.state.factory) as session:
        assert lease.next_claimable(session, Calibration) is None  # no runner takes it up again
    assert api.post("/api/calibrations", json=CAR).status_code == 202  # and another may start


def test_points_two_steps_out_search_only_the_model_the_nearest_calibrated_point_chose():
    """The default points tile the car's window: its scenario's drift and neighbours search every candidate model,
    the points further out the one the nearest calibrated point kept (a quarter of the episodes each)."""
    from types import SimpleNamespace

    from driftlab.core.calibration import CalibrationPoint
    from driftlab.core.calibration_run import _model_candidates, _models_for
    from driftlab.core.configure import preset_config

    given = preset_config("commonroad_std")  # 0.5 rad, 44 m
    run = SimpleNamespace(given=given, request=SimpleNamespace(sets={}))
    every = _model_candidates(given, {})
    assert len(every) == 4  # two rear models x two steering limits

    def document(sideslip_rad, coupling, limit_rad, completed=3):
        return {"points": [{"sideslip_rad": sideslip_rad, "radius_m": 44.0}], "completed": completed,
                "plant": {"model_drive_coupling": coupling}, "mpc": {"steer_limit_rad": limit_rad}}

    done = [document(0.5, False, 0.6), document(0.55, True, 1.066), document(0.45, False, 0.6)]
    assert _models_for(run, [CalibrationPoint(0.55, 44.0)], done) == (every, [])  # one step out
    assert _models_for(run, [CalibrationPoint(0.5, 30.0)], done) == (every, [])  # the other circles
    chosen, others = _models_for(run, [CalibrationPoint(0.6, 44.0)], done)
    assert chosen == [{"plant.model_drive_coupling": True, "mpc.steer_limit_rad": 1.066}]  # 0.55's choice
    # ... and the other three, where 0.55's model has no fit at 0.6 rad
    assert others == [{}, {"plant.model_drive_coupling": True}, {"mpc.steer_limit_rad": 1.066}]
    assert _models_for(run, [CalibrationPoint(0.6, 44.0)], []) == (every, [])  # nothing calibrated yet
    fixed = SimpleNamespace(given=given, request=SimpleNamespace(sets={"mpc.steer_limit_rad": 0.6}))
    assert _models_for(fixed, [CalibrationPoint(0.6, 44.0)], done) == ([{"plant.model_drive_coupling": True}], [{}])
