"""What the dashboard page asks of the API beyond jobs: notes, the search space, rescoring with progress."""

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from driftlab.core.config import Theta
from driftlab.core.robust import rescore_seeds
from driftlab.db import lease, storage
from driftlab.db import rescores as db_rescores
from driftlab.db.models import Rescore
from driftlab.worker.rescoring import run_rescore
from driftlab.worker.slots import EpisodeSlots
from tests.server.conftest import InThreadExecutor, in_process_client


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


def test_tabs_asking_at_once_share_one_fit(api, monkeypatch):
    """Twelve requests for the same job's search space while it is fitted: one fit, twelve equal answers; a new
    evaluation refits once."""
    from driftlab.core import search_space as module  # the service imports the fit when it first fits

    job = api.post("/api/jobs", json={"name": "sf", "iterations": 30, "model_correction": False}).json()
    _store(api, job["id"])
    fits = []
    real_fit = module.fit_models

    def counted_fit(*args):
        fits.append(1)
        return real_fit(*args)

    monkeypatch.setattr(module, "fit_models", counted_fit)
    api.app.state.heavy_reads.limit = 64  # the cap is tested apart
    url = f"/api/jobs/{job['id']}/search-space"
    with ThreadPoolExecutor(12) as pool:
        answers = list(pool.map(lambda _: api.get(url, params={"x": "c_lr", "y": "k", "grid": 6}).json(), range(12)))
    assert len(fits) == 1 and all(a == answers[0] for a in answers)
    _store(api, job["id"], n=1)
    assert api.get(url).json()["n_evaluations"] == 15 and len(fits) == 2


def test_heavy_reads_past_the_cap_are_a_503_with_retry_after(tmp_path):
    with in_process_client(tmp_path / "cap.db", max_heavy_reads=1) as client:
        job = client.post("/api/jobs", json={"name": "cap", "iterations": 20, "model_correction": False}).json()
        _store(client, job["id"])
        reads = client.app.state.heavy_reads
        reads.wait_s = 0.3  # how long one more waits for a slot before its 503
        assert reads.try_enter()  # the one slot, taken
        for path in (f"/api/jobs/{job['id']}/search-space", "/api/evaluations/1/recording.viser",
                     "/api/evaluations/1/replay.html"):
            busy = client.get(path)
            assert busy.status_code == 503 and busy.headers["retry-after"] == "2", path
            assert "DRIFTLAB_MAX_HEAVY_READS" in busy.json()["detail"]
        assert client.get("/api/jobs").status_code == 200 and client.get("/api/health").status_code == 200
        reads.leave()
        assert client.get(f"/api/jobs/{job['id']}/search-space").status_code == 200
        assert client.get("/api/evaluations/999/recording.viser").status_code == 404  # past the cap: the route's
        assert reads.try_enter()  # the slots were given back after each request, errors included
        reads.wait_s = 10.0
        threading.Timer(0.5, reads.leave).start()  # the slot comes free while the next request waits for it
        assert client.get(f"/api/jobs/{job['id']}/search-space").status_code == 200


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


def _with_a_best(api, name="r"):
    job = api.post("/api/jobs", json={"name": name, "iterations": 5}).json()
    with storage.transaction(api.app.state.factory) as session:
        storage.add_evaluation(session, job_id=job["id"], theta=Theta().as_dict(), J=-1.0, status="completed",
                               metrics={}, trigger_points=[], wall_ms=1.0, columns=["t_s"],
                               trajectory=np.zeros((1, 1)))
    return job["id"]


def _run_queued(api, executor, should_stop=lambda: False):
    """What the server's runner does with the next queued rescore (driftlab.worker.job_runner)."""
    factory = api.app.state.factory
    with storage.transaction(factory) as session:
        rescore_id = lease.next_claimable(session, Rescore)
        assert lease.claim(session, Rescore, row_id=rescore_id, runner="test-runner")
    return run_rescore(factory, rescore_id, executor, runner="test-runner", slots=EpisodeSlots(1),
                       owner=("rescore", rescore_id), should_stop=should_stop)


def test_rescore_is_queued_stored_and_reports_the_result(api):
    job = api.post("/api/jobs", json={"name": "none", "iterations": 5}).json()
    assert api.post(f"/api/jobs/{job['id']}/rescore", json={}).status_code == 404  # nothing to rescore yet
    assert api.get(f"/api/jobs/{job['id']}/rescore").json()["status"] == "none"
    job_id = _with_a_best(api)
    r = api.post(f"/api/jobs/{job_id}/rescore", json={"samples": 2})
    assert r.status_code == 202 and r.json()["samples"] == 2 and r.json()["status"] == "queued"
    busy = api.post(f"/api/jobs/{job_id}/rescore", json={"samples": 2})
    assert busy.status_code == 409 and "DELETE /api/jobs" in busy.json()["detail"]
    with ThreadPoolExecutor(1) as pool:
        assert _run_queued(api, InThreadExecutor(pool)) == "finished"
    state = api.get(f"/api/jobs/{job_id}/rescore").json()
    assert state["status"] == "finished" and state["done"] == 2, state
    assert state["result"]["samples"] == 2 and state["result"]["seeds"] == rescore_seeds(2)
    assert state["J_stored"] == -1.0
    by_phase = state["result"]["by_phase"]  # the default theta completes both episodes, drifts and flicks
    assert set(by_phase) == {"drift", "flick"}, by_phase
    for group in by_phase.values():
        assert set(group) == {"mean_abs_e_m", "max_abs_e_m", "rms_beta_err_rad", "episodes"} and group["episodes"] == 2
        assert 0.0 < group["mean_abs_e_m"] < group["max_abs_e_m"] and group["rms_beta_err_rad"] > 0.0
    assert api.post(f"/api/jobs/{job_id}/rescore", json={"samples": 0}).json()["errors"][0]["field"] == "samples"


def test_a_stopped_rescore_resumes_with_the_seeds_still_missing(api):
    job_id = _with_a_best(api)
    api.post(f"/api/jobs/{job_id}/rescore", json={"samples": 3})
    with ThreadPoolExecutor(1) as pool:
        executor = InThreadExecutor(pool)
        stop = lambda: executor.submitted >= 1  # noqa: E731  # the runner shuts down after the first episode
        assert _run_queued(api, executor, should_stop=stop) == "queued"
        first = api.get(f"/api/jobs/{job_id}/rescore").json()
        assert first["status"] == "queued" and first["done"] == 1, first
        resumed = InThreadExecutor(pool)
        assert _run_queued(api, resumed) == "finished"
    assert resumed.submitted == 2  # only the missing seeds ran again
    state = api.get(f"/api/jobs/{job_id}/rescore").json()
    assert state["done"] == 3 and state["result"]["seeds"] == rescore_seeds(3)


def test_a_rescore_resumed_over_a_sample_an_earlier_release_stored_summarizes_it(api):
    job_id = _with_a_best(api)
    api.post(f"/api/jobs/{job_id}/rescore", json={"samples": 3})
    with ThreadPoolExecutor(1) as pool:
        executor = InThreadExecutor(pool)
        assert _run_queued(api, executor, should_stop=lambda: executor.submitted >= 1) == "queued"
        with storage.transaction(api.app.state.factory) as session:  # as stored before samples had phases
            rescore = db_rescores.latest(session, job_id=job_id)
            [first] = rescore.samples
            assert "by_phase" in first
            rescore.samples = [{k: v for k, v in first.items() if k != "by_phase"}]
        assert _run_queued(api, InThreadExecutor(pool)) == "finished"
    result = api.get(f"/api/jobs/{job_id}/rescore").json()["result"]
    assert result["samples"] == 3 and result["completed"] == 3
    assert result["by_phase"]["drift"]["episodes"] == 2 and result["by_phase"]["flick"]["episodes"] == 2


def test_a_rescore_can_be_cancelled_and_then_started_again(api):
    job_id = _with_a_best(api)
    assert api.delete(f"/api/jobs/{job_id}/rescore").status_code == 404  # none to cancel
    api.post(f"/api/jobs/{job_id}/rescore", json={"samples": 4})
    r = api.delete(f"/api/jobs/{job_id}/rescore")
    assert r.status_code == 200 and r.json()["status"] == "cancelled"
    with storage.snapshot(api.app.state.factory) as session:
        assert lease.next_claimable(session, Rescore) is None  # no runner takes it
    assert api.post(f"/api/jobs/{job_id}/rescore", json={"samples": 1}).status_code == 202


def test_rescores_share_a_global_episode_budget(tmp_path):
    with in_process_client(tmp_path / "budget.db", max_rescore_episodes=5) as client:
        a, b = _with_a_best(client, "a"), _with_a_best(client, "b")
        assert client.post(f"/api/jobs/{a}/rescore", json={"samples": 4}).status_code == 202
        r = client.post(f"/api/jobs/{b}/rescore", json={"samples": 2})
        assert r.status_code == 422 and "DRIFTLAB_MAX_RESCORE_EPISODES" in r.json()["detail"], r.text
        assert r.json()["detail"].startswith("samples: rescores already wait for 4 episodes")


def test_deleting_a_job_deletes_its_rescores(api):
    job_id = _with_a_best(api)
    api.post(f"/api/jobs/{job_id}/rescore", json={"samples": 2})
    assert api.delete(f"/api/jobs/{job_id}").status_code == 204
    with storage.snapshot(api.app.state.factory) as session:
        assert db_rescores.episodes_outstanding(session) == 0


def test_a_rescore_counts_against_the_episodes_per_job_limit(tmp_path):
    with in_process_client(tmp_path / "quota.db", max_episodes_per_job=10) as client:
        job = client.post("/api/jobs", json={"name": "q", "iterations": 1, "robust_samples": 1,
                                             "confirm_samples": 0}).json()
        r = client.post(f"/api/jobs/{job['id']}/rescore", json={"samples": 11})
        assert r.status_code == 422 and r.json()["detail"].startswith("samples: 11 episodes exceed the limit of 10")


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
    assert form["plant_bounds"]["commonroad_std"]["k"][0] < 0 and "default" not in form["plant_bounds"]
