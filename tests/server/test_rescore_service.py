"""Rescores on a real server: run by the job runner (not a request thread), stored as they go, so ordinary
traffic cannot break them, a restart resumes them and a DELETE cancels them."""

import shutil
import sqlite3
import threading
import time

import httpx
import pytest

from tests.server_process import free_port, start_server, wait_for, wait_status

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI


def _finished_job(url) -> int:
    job = httpx.post(f"{url}/api/jobs", json={"name": "tuned", "iterations": 1, "robust_samples": 1,
                                              "confirm_samples": 0}).json()
    wait_status(url, job["id"], {"finished"}, timeout_s=300)
    return job["id"]


def _burst(url, job_id, clients=8, seconds=3.0):
    """``clients`` threads reading as fast as they can for ``seconds`` (the request threads come and go)."""
    stop = time.monotonic() + seconds

    def read():
        with httpx.Client(base_url=url, timeout=30) as client:
            while time.monotonic() < stop:
                client.get("/api/jobs")
                client.get(f"/api/jobs/{job_id}/rescore")

    threads = [threading.Thread(target=read) for _ in range(clients)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()


def test_a_rescore_outlives_a_burst_a_restart_and_can_be_cancelled(tmp_path):
    db = tmp_path / "driftlab.db"
    proc, url = start_server(db, free_port(), extra_args=("--workers", "1"))
    try:
        job_id = _finished_job(url)
        rescore = f"{url}/api/jobs/{job_id}/rescore"
        assert httpx.post(rescore, json={"samples": 6}).status_code == 202
        _burst(url, job_id)
        state = wait_for(rescore, lambda r: r["status"] not in ("queued", "running"), timeout_s=300, poll_s=0.5)
        assert state["status"] == "finished" and state["done"] == 6, state
        assert httpx.post(rescore, json={"samples": 0}).status_code == 422

        assert httpx.post(rescore, json={"samples": 12}).status_code == 202
        wait_for(rescore, lambda r: r["done"] >= 1, timeout_s=300)
        proc.terminate()
        proc.wait(timeout=60)
        proc, url = start_server(db, free_port(), extra_args=("--workers", "1"))
        rescore = f"{url}/api/jobs/{job_id}/rescore"
        state = wait_for(rescore, lambda r: r["status"] not in ("queued", "running"), timeout_s=300, poll_s=0.5)
        assert state["status"] == "finished" and state["done"] == 12, state
        assert state["result"]["samples"] == 12 and len(set(state["result"]["seeds"])) == 12

        assert httpx.post(rescore, json={"samples": 500}).status_code == 202
        cancelled = httpx.delete(rescore)
        assert cancelled.status_code == 200 and cancelled.json()["status"] == "cancelled"
        assert httpx.delete(rescore).status_code == 404
        # The runner runs one rescore at a time: the next one finishing means the cancelled one let go.
        assert httpx.post(rescore, json={"samples": 1}).status_code == 202
        state = wait_for(rescore, lambda r: r["status"] not in ("queued", "running"), timeout_s=300, poll_s=0.5)
        assert state["status"] == "finished" and state["done"] == 1, state
    finally:
        proc.terminate()
        proc.wait(timeout=60)


def test_after_a_clean_stop_the_database_file_alone_holds_every_evaluation(tmp_path):
    db = tmp_path / "driftlab.db"
    proc, url = start_server(db, free_port(), extra_args=("--workers", "1"))
    try:
        job_id = _finished_job(url)
        n_done = httpx.get(f"{url}/api/jobs/{job_id}").json()["n_done"]
    finally:
        proc.terminate()
        proc.wait(timeout=60)
    assert not (tmp_path / "driftlab.db-wal").exists() or (tmp_path / "driftlab.db-wal").stat().st_size == 0
    copy = tmp_path / "copy" / "driftlab.db"
    copy.parent.mkdir()
    shutil.copyfile(db, copy)  # the file alone: no -wal, no -shm beside it
    with sqlite3.connect(copy) as connection:
        assert connection.execute("SELECT count(*) FROM evaluations WHERE job_id = ?", (job_id,)).fetchone() \
            == (n_done,)


def test_the_servers_runner_runs_a_calibration_beside_the_jobs(tmp_path):
    proc, url = start_server(tmp_path / "driftlab.db", free_port(), extra_args=("--workers", "2"))
    try:
        # Queueing a calibration checks the car's drift at its points: ~2.5 s of physics on an idle 2-core machine,
        # beyond httpx's 5 s default under the suite's load (a request that works, not one that hangs).
        queued = httpx.post(f"{url}/api/calibrations", json={
            "plant": "commonroad_std", "points": "0.5@44", "iterations": 2, "seeds": 1,
            "config": {"plant.model_drive_coupling": False, "mpc.steer_limit_rad": 0.6}}, timeout=60)
        assert queued.status_code == 202, queued.text
        job = httpx.post(f"{url}/api/jobs", json={"iterations": 2, "robust_samples": 1, "confirm_samples": 0}).json()
        state = wait_for(f"{url}/api/calibrations/{queued.json()['id']}",
                         lambda r: r["status"] not in ("queued", "running"), timeout_s=300, poll_s=0.5)
        assert state["status"] == "finished" and len(state["profile_ids"]) == 1, state
        wait_status(url, job["id"], {"finished"}, timeout_s=300)  # the job ran beside it
    finally:
        proc.terminate()
        proc.wait(timeout=60)


def test_sigterm_with_a_job_a_rescore_and_a_calibration_running_exits_within_dockers_grace(tmp_path):
    """`docker stop` sends SIGTERM and kills 10 s later: the server hands back every lease, checkpoints the database
    and exits before that, the file alone holding every acknowledged evaluation, and a restarted server takes each
    piece of work up again."""
    import signal

    db = tmp_path / "driftlab.db"
    proc, url = start_server(db, free_port(), extra_args=("--workers", "2"))
    try:
        tuned = _finished_job(url)
        job = httpx.post(f"{url}/api/jobs", json={"name": "long", "iterations": 400}).json()["id"]
        assert httpx.post(f"{url}/api/jobs/{tuned}/rescore", json={"samples": 60}).status_code == 202
        calibration = httpx.post(f"{url}/api/calibrations", json={  # ~2.5 s of drift checks (above)
            "plant": "commonroad_std", "points": "0.5@44", "iterations": 40, "seeds": 2}, timeout=60).json()["id"]
        wait_for(f"{url}/api/jobs/{job}", lambda j: j["n_done"] >= 2, timeout_s=300)
        wait_for(f"{url}/api/jobs/{tuned}/rescore", lambda r: r["done"] >= 1, timeout_s=300)
        wait_for(f"{url}/api/calibrations/{calibration}", lambda c: c["status"] == "running", timeout_s=300)
        acknowledged = httpx.get(f"{url}/api/jobs/{job}").json()["n_done"]
        started = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
        exit_s = time.monotonic() - started
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert exit_s <= 10.0, f"{exit_s:.1f} s to exit"
    assert not (tmp_path / "driftlab.db-wal").exists() or (tmp_path / "driftlab.db-wal").stat().st_size == 0
    with sqlite3.connect(db) as connection:
        (stored,), = connection.execute("SELECT count(*) FROM evaluations WHERE job_id = ?", (job,)).fetchall()
        statuses = {table: connection.execute(f"SELECT status, runner_id FROM {table}").fetchall()[-1]
                    for table in ("rescores", "calibrations")}
        (job_status,), = connection.execute("SELECT status FROM jobs WHERE id = ?", (job,)).fetchall()
    assert stored >= acknowledged and job_status == "queued"
    assert statuses == {"rescores": ("queued", None), "calibrations": ("queued", None)}  # handed back
    proc, url = start_server(db, free_port(), extra_args=("--workers", "2"))
    try:
        wait_for(f"{url}/api/jobs/{job}", lambda j: j["n_done"] > stored, timeout_s=300)
        before = httpx.get(f"{url}/api/jobs/{tuned}/rescore").json()["done"]
        wait_for(f"{url}/api/jobs/{tuned}/rescore", lambda r: r["done"] > before, timeout_s=300)
        wait_for(f"{url}/api/calibrations/{calibration}", lambda c: c["status"] == "running", timeout_s=300)
    finally:
        proc.terminate()
        proc.wait(timeout=60)
