"""The REST API against a real server process and a real SQLite file."""

import csv
import io
import time

import httpx
import pytest

from driftlab.core.config import THETA_KEYS, Theta
from tests.server_process import free_port as _free_port
from tests.server_process import start_server as _start
from tests.server_process import wait_released
from tests.server_process import wait_status as _wait_status

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    db = tmp_path_factory.mktemp("api") / "driftlab.db"
    proc, url = _start(db, _free_port())
    yield url, db
    proc.terminate()
    proc.wait(timeout=30)


def test_a_small_job_runs_to_the_end(server):
    url, db = server
    r = httpx.post(f"{url}/api/jobs", json={"name": "small", "iterations": 12, "seed_points": 6})
    assert r.status_code == 201, r.text
    job = r.json()
    assert job["status"] == "queued" and job["iterations"] == 12
    done = _wait_status(url, job["id"], {"finished"})
    assert done["n_done"] == 12 and done["progress"] == 1.0
    evals = httpx.get(f"{url}/api/jobs/{job['id']}/evaluations").json()
    assert [e["index"] for e in evals] == list(range(12))
    assert all(set(e["theta"]) == {"c_lr", "c_rl", "dV", "k", "model_mu_scale", "model_c_scale"} for e in evals)
    # A job with the model corrections asks the untuned theta first. Evaluations are stored in order of completion,
    # and a completing one runs its confirmation seeds while failing ones end in milliseconds: it may land anywhere.
    assert [e["theta"] for e in evals].count(Theta().as_dict()) == 1
    later = httpx.get(f"{url}/api/jobs/{job['id']}/evaluations", params={"after": 8}).json()
    assert [e["index"] for e in later] == [9, 10, 11]
    best = httpx.get(f"{url}/api/jobs/{job['id']}/best").json()
    completed = [e["J"] for e in evals if e["completed"]]
    assert best["J"] == min(completed or [e["J"] for e in evals])  # before a completion: the least-bad failure
    assert done["best"]["id"] == best["id"]
    assert db.exists() and db.stat().st_size > 0


def test_robust_job_stores_each_seed_and_exports_theta_at_full_precision(server):
    url, _ = server
    r = httpx.post(f"{url}/api/jobs", json={"name": "robust", "iterations": 3, "seed_points": 3,
                                            "robust_samples": 2, "seed": 1})
    assert r.status_code == 201, r.text
    assert r.json()["spec"]["robust_samples"] == 2
    _wait_status(url, r.json()["id"], {"finished"})
    evals = httpx.get(f"{url}/api/jobs/{r.json()['id']}/evaluations").json()
    for e in evals:
        seeds = [s["seed"] for s in e["seeds"]]
        assert seeds in ([64, 65], [64, 65, 66, 67, 68, 69])  # a best so far is confirmed on 4 more seeds
        assert e["J"] == pytest.approx(sum(s["J"] for s in e["seeds"]) / len(seeds), abs=1e-12)
        assert e["completed"] == all(s["status"] == "completed" for s in e["seeds"])
        assert e["trajectory_seed"] in seeds and e["metrics"]["n_samples"] == len(seeds)
    assert any(len(e["seeds"]) == 6 for e in evals) == any(e["completed"] for e in evals)
    best = httpx.get(f"{url}/api/jobs/{r.json()['id']}/best").json()
    assert best["seeds"] == next(e for e in evals if e["id"] == best["id"])["seeds"]
    assert httpx.get(f"{url}/api/jobs/{r.json()['id']}").json()["best"]["seeds"] == best["seeds"]
    exported = httpx.get(f"{url}/api/jobs/{r.json()['id']}/evaluations", params={"format": "csv"})
    assert exported.status_code == 200 and "attachment" in exported.headers["content-disposition"]
    rows = list(csv.DictReader(io.StringIO(exported.text)))
    assert len(rows) == 3
    for row, e in zip(rows, evals, strict=True):
        assert {k: float(row[k]) for k in THETA_KEYS} == e["theta"]  # bit-exact round trip
        assert float(row["J"]) == e["J"] and row["seeds"] == " ".join(str(s["seed"]) for s in e["seeds"])


@pytest.mark.parametrize("value", [0, 65, 1.5, "2"])
def test_robust_samples_out_of_range_is_a_422_naming_it(server, value):
    url, _ = server
    r = httpx.post(f"{url}/api/jobs", json={"iterations": 3, "robust_samples": value})
    assert r.status_code == 422 and "robust_samples" in r.json()["detail"]


@pytest.mark.parametrize(("body", "field"), [
    ({"model_correction": "yes"}, "model_correction"),
    ({"model_correction": False, "bounds": {"model_c_scale": [0.9, 1.1]}}, "bounds.model_c_scale"),
    ({"bounds": {"model_mu_scale": [0.9, 2.5]}}, "bounds.model_mu_scale")])
def test_model_correction_settings_are_checked_and_nothing_is_stored(server, body, field):
    url, _ = server
    before = len(httpx.get(f"{url}/api/jobs").json())
    r = httpx.post(f"{url}/api/jobs", json={"iterations": 3, **body})
    assert r.status_code == 422 and field in r.text, r.text
    assert len(httpx.get(f"{url}/api/jobs").json()) == before


def test_a_job_without_model_correction_learns_the_papers_four_parameters(server):
    url, _ = server
    r = httpx.post(f"{url}/api/jobs", json={"iterations": 3, "seed_points": 3, "model_correction": False})
    assert r.status_code == 201, r.text
    assert r.json()["spec"]["model_correction"] is False and set(r.json()["spec"]["bounds"]) == {"c_lr", "c_rl",
                                                                                                  "dV", "k"}


def test_trajectory_downloads_parse(server):
    url, _ = server
    job = next((j for j in httpx.get(f"{url}/api/jobs").json() if j["name"] == "small"), None)
    if job is None:  # run on its own: a finished job of its own to download from
        created = httpx.post(f"{url}/api/jobs", json={"name": "downloads", "iterations": 4, "seed_points": 4}).json()
        job = _wait_status(url, created["id"], {"finished"})
    evaluation = httpx.get(f"{url}/api/jobs/{job['id']}/best").json()
    r = httpx.get(f"{url}/api/evaluations/{evaluation['id']}/trajectory", params={"format": "csv"})
    assert r.status_code == 200 and "attachment" in r.headers["content-disposition"]
    described = r.headers["link"].split(";")[0].strip("<>")  # the metadata: the JSON download's
    js = httpx.get(f"{url}{described}").json()
    meta = js["metadata"]
    seed = evaluation["trajectory_seed"]
    assert meta["evaluation_id"] == evaluation["id"] and meta["job_id"] == job["id"] and meta["seed"] == seed
    assert meta["theta"] == {**Theta().as_dict(), **evaluation["theta"]} and meta["J"] == evaluation["J"]
    assert meta["J_episode"] == next(s["J"] for s in evaluation["seeds"] if s["seed"] == seed)
    assert meta["n_seeds"] == len(evaluation["seeds"]) and meta["config"] == job["spec"]["config"]
    assert meta["phases"] == evaluation["metrics"]["phases"] and meta["phases"][0]["phase"] == "left_drift"
    rows = list(csv.reader(io.StringIO(r.text)))
    header, body = rows[0], rows[1:]
    assert "beta_rad" in header and "t_s" in header
    t = [float(row[header.index("t_s")]) for row in body]
    assert len(t) > 10 and t[0] == 0.0
    assert all(abs(b - a - 0.05) < 1e-9 for a, b in zip(t, t[1:], strict=False))  # one row per 0.05 s control step
    assert {row[header.index("phase")] for row in body} <= {"0", "1", "2", "3", "4", "5"}  # integers, not 2.0
    assert js["columns"] == header and len(js["rows"]) == len(body) and js["metadata"] == meta
    assert all(isinstance(row[header.index("phase")], int) for row in js["rows"])


def test_pause_and_resume(server):
    url, _ = server
    job = httpx.post(f"{url}/api/jobs", json={"iterations": 400, "seed_points": 5}).json()
    time.sleep(1.0)
    paused = httpx.post(f"{url}/api/jobs/{job['id']}/pause")
    assert paused.status_code == 200
    job_now = _wait_status(url, job["id"], {"paused"})
    n_paused = wait_released(url, job["id"])["n_done"]  # evaluations in flight are stored, then nothing more
    time.sleep(1.0)
    assert httpx.get(f"{url}/api/jobs/{job['id']}").json()["n_done"] == n_paused
    assert n_paused >= job_now["n_done"]
    assert httpx.post(f"{url}/api/jobs/{job['id']}/pause").status_code == 409
    assert httpx.post(f"{url}/api/jobs/{job['id']}/resume").status_code == 200
    deadline = time.time() + 60
    while httpx.get(f"{url}/api/jobs/{job['id']}").json()["n_done"] <= n_paused and time.time() < deadline:
        time.sleep(0.2)
    assert httpx.get(f"{url}/api/jobs/{job['id']}").json()["n_done"] > n_paused
    httpx.post(f"{url}/api/jobs/{job['id']}/pause")
    _wait_status(url, job["id"], {"paused"})
    evals = httpx.get(f"{url}/api/jobs/{job['id']}/evaluations").json()
    assert [e["index"] for e in evals] == list(range(len(evals)))


def test_a_commonroad_job_is_one_config_key(server):
    url, _ = server
    r = httpx.post(f"{url}/api/jobs", json={"iterations": 1, "seed_points": 1, "name": "commonroad",
                                            "config": {"plant.model": "commonroad_std", "scenario.sideslip_rad": 0.5}})
    assert r.status_code == 201, r.text
    config = r.json()["spec"]["config"]
    assert config["plant"]["model"] == "commonroad_std" and config["mpc"]["q_steer"] != 122.5  # the car's weights
    # Creating the job did no physics: the controller's model is fitted to the car when a runner claims the job,
    # and stored with it (the job re-runs from what is stored).
    assert "vehicle" not in config and "initial_rear_slip" not in config["plant"]
    done = _wait_status(url, r.json()["id"], {"finished"}, timeout_s=300)  # behind the module's other jobs
    assert done["n_done"] == 1
    stored = done["spec"]["config"]
    assert stored["vehicle"]["mass_kg"] == pytest.approx(1093.3, 0.01) and stored["vehicle"]["steer_offset_rad"] != 0
    assert stored["plant"]["initial_rear_slip"] < 0 and stored["mpc"] == config["mpc"]


def test_concurrent_reads_while_a_job_writes(server):
    from concurrent.futures import ThreadPoolExecutor

    url, _ = server
    job = httpx.post(f"{url}/api/jobs", json={"iterations": 40, "seed_points": 5}).json()
    deadline = time.time() + 60
    while httpx.get(f"{url}/api/jobs/{job['id']}").json()["n_done"] < 2 and time.time() < deadline:
        time.sleep(0.1)
    first = httpx.get(f"{url}/api/jobs/{job['id']}/evaluations").json()[0]

    def read(i):
        with httpx.Client(timeout=30) as client:
            paths = [f"/api/jobs/{job['id']}/evaluations", f"/api/evaluations/{first['id']}/trajectory",
                     f"/api/jobs/{job['id']}", f"/api/jobs/{job['id']}/evaluations?after={i % 5}"]
            return [client.get(url + p).status_code for p in paths]

    with ThreadPoolExecutor(8) as pool:
        codes = [c for batch in pool.map(read, range(40)) for c in batch]
    assert codes.count(200) == len(codes) == 160
    httpx.post(f"{url}/api/jobs/{job['id']}/pause")
