"""What the dashboard page asks of the API beyond jobs: notes, the search space, rescoring with progress."""

import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from driftlab.core.config import Theta
from driftlab.db import storage
from driftlab.worker.executors import evaluate_episode
from driftlab.worker.rescoring import RescoreRunner
from tests.server.conftest import in_process_client


def _store(api, job_id, n=14):
    """n evaluations spread over the job's box: J depends on k only; the largest c_lr fail."""
    rng = np.random.default_rng(0)
    factory = api.app.state.factory
    bounds = api.get(f"/api/jobs/{job_id}").json()["spec"]["bounds"]
    with storage.transaction(factory) as session:
        for _ in range(n):
            theta = {k: float(lo + (hi - lo) * rng.random()) for k, (lo, hi) in bounds.items()}
            ok = theta["c_lr"] < 0.03
            storage.add_evaluation(session, job_id=job_id, theta=theta, J=10 * theta["k"] if ok else 9.0,
                                   status="completed" if ok else "left_track", metrics={}, trigger_points=[],
                                   wall_ms=1.0, columns=["t_s"], trajectory=np.zeros((1, 1)))


def test_notes_are_kept_with_the_job_and_a_patch_needs_something(api):
    job = api.post("/api/jobs", json={"name": "n", "iterations": 5}).json()
    assert job["notes"] == ""
    r = api.patch(f"/api/jobs/{job['id']}", json={"notes": "flick too late; try c_lr up"})
    assert r.status_code == 200 and r.json()["notes"] == "flick too late; try c_lr up"
    assert r.json()["iterations"] == 5  # notes alone leave the budget
    assert api.get(f"/api/jobs/{job['id']}").json()["notes"] == "flick too late; try c_lr up"
    r = api.patch(f"/api/jobs/{job['id']}", json={})
    assert r.status_code == 422 and "iterations, notes or both" in r.json()["detail"]
    r = api.patch(f"/api/jobs/{job['id']}", json={"notes": "x" * 10_001})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "notes"


def test_the_search_space_of_a_stored_history(api):
    job = api.post("/api/jobs", json={"name": "s", "iterations": 20, "model_correction": False}).json()
    _store(api, job["id"])
    r = api.get(f"/api/jobs/{job['id']}/search-space", params={"x": "c_lr", "y": "k", "grid": 8})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["n_evaluations"] == 14 and body["parameters"] == ["c_lr", "c_rl", "dV", "k"]
    assert len(body["mean_J"]) == 8 and len(body["mean_J"][0]) == 8 and len(body["x_values"]) == 8
    assert body["p_failure"] is not None and set(body["held"]) == {"c_rl", "dV"}
    mean = np.array(body["mean_J"])
    assert mean[-1].mean() > mean[0].mean()  # J grows with k (the rows)
    assert max(body["importance"], key=body["importance"].get) == "k"
    default = api.get(f"/api/jobs/{job['id']}/search-space").json()  # the two most important by default
    assert "k" in (default["x"], default["y"])


def test_bad_search_space_requests_name_the_field(api):
    job = api.post("/api/jobs", json={"name": "b", "iterations": 5, "model_correction": False}).json()
    r = api.get(f"/api/jobs/{job['id']}/search-space", params={"x": "mass"})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "query.x"  # not a theta key at all
    r = api.get(f"/api/jobs/{job['id']}/search-space", params={"x": "model_mu_scale"})
    assert r.status_code == 422 and r.json()["detail"].startswith("x: 'model_mu_scale' is not a parameter of this job")
    r = api.get(f"/api/jobs/{job['id']}/search-space", params={"x": "k", "y": "k"})
    assert r.status_code == 422 and r.json()["detail"].startswith("y: choose two different parameters")
    r = api.get(f"/api/jobs/{job['id']}/search-space", params={"grid": 500})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "query.grid"
    assert api.get("/api/jobs/999/search-space").status_code == 404


def test_rescore_reports_progress_and_the_result(api):
    job = api.post("/api/jobs", json={"name": "r", "iterations": 5}).json()
    assert api.post(f"/api/jobs/{job['id']}/rescore", json={}).status_code == 404  # nothing to rescore yet
    assert api.get(f"/api/jobs/{job['id']}/rescore").json()["status"] == "none"
    with storage.transaction(api.app.state.factory) as session:
        storage.add_evaluation(session, job_id=job["id"], theta=Theta().as_dict(), J=-1.0, status="completed",
                               metrics={}, trigger_points=[], wall_ms=1.0, columns=["t_s"],
                               trajectory=np.zeros((1, 1)))
    pool = ThreadPoolExecutor(1)
    api.app.state.rescores = RescoreRunner(api.app.state.factory, open_executor=lambda: _InThread(pool))
    r = api.post(f"/api/jobs/{job['id']}/rescore", json={"samples": 2})
    assert r.status_code == 202 and r.json()["samples"] == 2
    assert api.post(f"/api/jobs/{job['id']}/rescore", json={"samples": 2}).status_code in (202, 409)
    deadline = time.time() + 120
    while (state := api.get(f"/api/jobs/{job['id']}/rescore").json())["status"] == "running":
        assert time.time() < deadline, state
        time.sleep(0.1)
    assert state["status"] == "finished" and state["done"] == 2, state
    assert state["result"]["samples"] == 2 and len(state["result"]["seeds"]) == 2
    assert api.post(f"/api/jobs/{job['id']}/rescore", json={"samples": 0}).json()["errors"][0]["field"] == "samples"
    pool.shutdown()


def test_a_rescore_counts_against_the_episodes_per_job_limit(tmp_path):
    with in_process_client(tmp_path / "quota.db", max_episodes_per_job=10) as client:
        job = client.post("/api/jobs", json={"name": "q", "iterations": 1, "robust_samples": 1,
                                             "confirm_samples": 0}).json()
        r = client.post(f"/api/jobs/{job['id']}/rescore", json={"samples": 11})
        assert r.status_code == 422 and r.json()["detail"].startswith("samples: 11 episodes exceed the limit of 10")


class _InThread:
    """The executor interface on a thread pool: the real episodes, in this process."""

    def __init__(self, pool):
        self.pool = pool

    def submit(self, theta, config_doc, seed=0):
        return self.pool.submit(evaluate_episode, theta, config_doc, seed)

    def shutdown(self):
        pass


def test_the_config_diff_names_each_setting_that_differs(api):
    a = api.post("/api/jobs", json={"name": "a", "iterations": 5}).json()
    b = api.post("/api/jobs", json={"name": "b", "iterations": 7, "bounds": {"k": [0.0, 0.05]},
                                    "config": {"plant.steer_lag_s": 0.05}}).json()
    body = api.get("/api/compare/config", params={"jobs": f"{a['id']},{b['id']}"}).json()
    diff = {d["key"]: d["values"] for d in body["differences"]}
    assert diff == {"iterations": [5, 7], "bounds.k": [[0.0, 0.12], [0.0, 0.05]],
                    "config.plant.steer_lag_s": [0.03, 0.05]}
    assert [j["name"] for j in body["jobs"]] == ["a", "b"]


def test_the_job_form_turns_each_plant_preset_into_config_keys(api):
    form = api.get("/api/config/job-form").json()
    nominal = form["plant_presets"]["nominal"]
    assert nominal["plant.friction_circle"] is False and form["plant_presets"]["default"] == {}
    job = api.post("/api/jobs", json={"name": "nominal", "iterations": 5, "config": nominal})
    assert job.status_code == 201, job.text
    assert job.json()["spec"]["config"]["plant"]["friction_circle"] is False
    assert form["default_bounds"]["k"] == [0.0, 0.12] and form["limits"]["iterations"] == [1, 5000]
