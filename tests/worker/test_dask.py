"""Episodes on a real Dask cluster: `dask scheduler` and `dask worker` processes on loopback."""

import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from driftlab.db import storage

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI

BIN = os.path.dirname(sys.executable)
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "PATH": BIN + os.pathsep + os.environ["PATH"]}


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _scheduler(port):
    proc = subprocess.Popen([os.path.join(BIN, "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                             "--no-dashboard"], env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    while time.time() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return proc
        time.sleep(0.2)
    proc.kill()
    raise RuntimeError("the Dask scheduler did not start")


def _worker(address):
    # No nanny: one process per worker, so SIGKILL takes the worker down for good.
    return subprocess.Popen([os.path.join(BIN, "dask"), "worker", address, "--nthreads", "1", "--no-nanny",
                             "--no-dashboard", "--host", "127.0.0.1"], env=ENV, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def _kill_all(processes):
    for proc in processes:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _wait_workers(address, n, timeout_s=90):
    from distributed import Client

    with Client(address, timeout=30, set_as_default=False) as client:
        client.wait_for_workers(n, timeout=timeout_s)


def _tune(db, address, *extra):
    return subprocess.Popen([sys.executable, "-m", "driftlab.cli", "tune", "--db", str(db), "--dask", address,
                             "--robust-samples", "2", "--confirm-samples", "0", "--seed-points", "6", *extra],
                            env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _n_done(db, name):
    try:
        factory = storage.open_database(f"sqlite:///{db}")
        with storage.transaction(factory) as session:
            job = storage.find_job(session, name=name)
            return 0 if job is None else storage.count_evaluations(session, job_id=job.id)
    except Exception:
        return 0


@pytest.fixture
def cluster():
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes = [_scheduler(port)]
    processes += [_worker(address) for _ in range(3)]
    _wait_workers(address, 3)
    yield address, processes
    _kill_all(processes)


def test_a_job_survives_a_worker_killed_mid_job(cluster, tmp_path):
    address, processes = cluster
    db = tmp_path / "dask.db"
    tune = _tune(db, address, "--iterations", "24", "--name", "dask")
    deadline = time.time() + 120
    while _n_done(db, "dask") < 6 and time.time() < deadline:
        time.sleep(0.2)
    assert _n_done(db, "dask") >= 6
    processes[1].send_signal(signal.SIGKILL)  # a worker, mid-job
    out, err = tune.communicate(timeout=300)
    assert tune.returncode == 0, err
    result = json.loads(out)
    assert result["status"] == "finished" and result["n_done"] == 24
    factory = storage.open_database(f"sqlite:///{db}")
    with storage.transaction(factory) as session:
        evals = storage.evaluations(session, job_id=result["id"])
        indexes = [e.index for e in evals]
        thetas = {tuple(sorted(e.theta.items())) for e in evals}
        runs = [(e.status, [s["seed"] for s in e.seeds], [s["status"] for s in e.seeds]) for e in evals]
    assert indexes == list(range(24)) and len(thetas) == 24
    # Every evaluation has each of its episodes exactly once; one whose first seed failed may stop there (its
    # unstarted seed is skipped: the evaluation fails whatever it does).
    for status, seeds, statuses in runs:
        assert seeds == [0, 1] or (seeds == [0] and statuses[0] != "completed" and status != "completed")


def test_a_lost_scheduler_pauses_the_job_and_it_resumes_when_the_scheduler_is_back(tmp_path):
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    db = tmp_path / "lost.db"
    processes = [_scheduler(port), _worker(address)]
    try:
        _wait_workers(address, 1)
        tune = _tune(db, address, "--iterations", "400", "--name", "lost")
        deadline = time.time() + 120
        while _n_done(db, "lost") < 3 and time.time() < deadline:
            time.sleep(0.2)
        processes[0].send_signal(signal.SIGKILL)  # the scheduler goes away
        out, err = tune.communicate(timeout=300)
        assert json.loads(out)["status"] == "paused", err
        assert "paused: episode executor unreachable" in err and "Traceback" not in err
        stopped_at = _n_done(db, "lost")
        processes[1].kill()
        processes = [_scheduler(port), _worker(address)]
        _wait_workers(address, 1)
        again = _tune(db, address, "--iterations", f"{stopped_at + 4}", "--name", "lost")
        out, err = again.communicate(timeout=300)
        assert again.returncode == 0, err
        assert json.loads(out)["status"] == "finished" and json.loads(out)["n_done"] == stopped_at + 4
    finally:
        _kill_all(processes)


def test_the_server_resumes_a_job_by_itself_when_its_scheduler_returns(tmp_path):
    import httpx

    from tests.server_process import free_port, start_server, wait_status

    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes = [_scheduler(port), _worker(address)]
    server = None
    try:
        _wait_workers(address, 1)
        server, url = start_server(tmp_path / "srv.db", free_port(), {"DRIFTLAB_DASK_ADDRESS": address})
        job = httpx.post(f"{url}/api/jobs", json={"iterations": 400, "seed_points": 5, "robust_samples": 1}).json()
        deadline = time.time() + 120
        while httpx.get(f"{url}/api/jobs/{job['id']}").json()["n_done"] < 3 and time.time() < deadline:
            time.sleep(0.2)
        processes[0].send_signal(signal.SIGKILL)
        paused = wait_status(url, job["id"], {"paused"}, timeout_s=120)
        assert paused["error"].startswith("episode executor unreachable")
        assert httpx.get(f"{url}/api/health").json() == {"status": "ok"}  # the API never waits on Dask
        n_paused = paused["n_done"]
        processes[1].kill()
        processes = [_scheduler(port), _worker(address)]
        # A new scheduler and worker start, the server reconnects and the job runs on: at load ~19 (two copies of
        # the suite at once) 120 s was not always enough.
        deadline = time.time() + 300
        while httpx.get(f"{url}/api/jobs/{job['id']}").json()["n_done"] <= n_paused + 2 and time.time() < deadline:
            time.sleep(0.5)
        now = httpx.get(f"{url}/api/jobs/{job['id']}").json()
        assert now["n_done"] > n_paused + 2 and now["status"] == "running" and now["error"] is None
        httpx.post(f"{url}/api/jobs/{job['id']}/pause")
        wait_status(url, job["id"], {"paused"})
    finally:
        if server is not None:
            server.terminate()
            server.wait(timeout=30)
        _kill_all(processes)


def test_rescore_runs_on_the_cluster_with_the_same_result_as_locally(cluster, tmp_path):
    address, _ = cluster
    db = tmp_path / "rescore.db"
    tuned = _tune(db, address, "--iterations", "3", "--name", "r")
    tuned.communicate(timeout=300)
    args = [sys.executable, "-m", "driftlab.cli", "rescore", "--name", "r", "--db", str(db), "--samples", "4"]
    on_dask = subprocess.run([*args, "--dask", address], env=ENV, capture_output=True, text=True, timeout=300)
    local = subprocess.run(args, env=ENV, capture_output=True, text=True, timeout=300)
    assert on_dask.returncode == 0 and local.returncode == 0, on_dask.stderr + local.stderr
    a, b = json.loads(on_dask.stdout), json.loads(local.stdout)
    assert a["J_mean"] == b["J_mean"] and a["seeds"] == b["seeds"]  # pure episodes: the executor does not matter


def test_a_robustness_study_on_dask_stores_the_same_cells_as_the_local_pool(cluster, tmp_path):
    address, _ = cluster
    args = ["study", "robustness", "--theta", "c_lr=0.021,k=0.06", "--grid", "plant.friction_scale=1.0,1.1",
            "--grid", "plant.mass_scale=0.95,1.05", "--robust-samples", "2", "--seed", "5", "--name", "grid"]
    results = []
    for db, extra in ((tmp_path / "dask.db", ["--dask", address]), (tmp_path / "local.db", ["--workers", "1"])):
        run = subprocess.run([sys.executable, "-m", "driftlab.cli", *args, "--db", str(db), *extra], env=ENV,
                             capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr
        results.append(json.loads(run.stdout))
    on_dask, local = results
    assert on_dask["status"] == local["status"] == "finished"
    assert [(c["settings"], c["status"], c["J"]) for c in on_dask["cells"]] == [
        (c["settings"], c["status"], c["J"]) for c in local["cells"]]


def test_a_job_takes_more_episodes_at_once_when_dask_workers_join_mid_job(tmp_path):
    """A job started on a one-thread cluster keeps one episode in flight; two workers join mid-job and the same job,
    never restarted, keeps more in flight at once on the grown cluster (its slots follow the cluster)."""
    from distributed import Client

    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes = [_scheduler(port), _worker(address)]
    tune = None
    try:
        _wait_workers(address, 1)
        db = tmp_path / "grow.db"
        tune = _tune(db, address, "--iterations", "400", "--name", "grow")
        with Client(address, timeout=30, set_as_default=False) as client:
            def in_flight():
                return sum(len(tasks) for tasks in client.processing().values())

            seen_alone = 0
            deadline = time.time() + 120
            while _n_done(db, "grow") < 3 and time.time() < deadline:
                seen_alone = max(seen_alone, in_flight())
                time.sleep(0.05)
            assert _n_done(db, "grow") >= 3 and seen_alone == 1  # one worker thread: one episode at a time
            processes += [_worker(address), _worker(address)]
            client.wait_for_workers(3, timeout=90)
            seen_grown, deadline = 0, time.time() + 120
            while seen_grown < 2 and time.time() < deadline:
                seen_grown = max(seen_grown, in_flight())
                time.sleep(0.02)
            assert seen_grown >= 2, "the job kept one episode in flight on three workers"
        assert tune.poll() is None  # the same process, never restarted
    finally:
        if tune is not None:
            tune.kill()
            tune.wait()
        _kill_all(processes)
