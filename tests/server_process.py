"""A real ``driftlab serve`` process on a free port with its own SQLite file, for end-to-end tests."""

import os
import socket
import subprocess
import sys
import tempfile
import time
from datetime import timedelta
from pathlib import Path

import httpx

from driftlab.db import storage
from driftlab.db.lease import LEASE_TIMEOUT_S, naive
from driftlab.db.models import Job, utcnow


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(db_path, port, env_extra=None, extra_args=()):
    env = {**os.environ, "OMP_NUM_THREADS": "1", **(env_extra or {})}
    # The server's log goes to a file: an undrained pipe would block the server once it fills.
    log = tempfile.NamedTemporaryFile(prefix="driftlab-serve-", suffix=".log", delete=False)
    proc = subprocess.Popen([sys.executable, "-m", "driftlab.cli", "serve", "--port", str(port), "--db", str(db_path),
                             *extra_args], env=env, stdout=subprocess.DEVNULL, stderr=log)
    proc.log_path = log.name  # the server's stderr, for tests that read what it logged
    url = f"http://127.0.0.1:{port}"
    for _ in range(150):
        try:
            if httpx.get(f"{url}/api/health", timeout=1).json() == {"status": "ok"}:
                return proc, url
        except httpx.HTTPError:
            time.sleep(0.1)
    proc.kill()
    proc.wait()
    raise RuntimeError(Path(log.name).read_text())


def wait_for(resource_url, done, timeout_s=120, poll_s=0.2):
    """GET ``resource_url`` until ``done(body)`` holds and return that body (AssertionError on timeout)."""
    deadline = time.time() + timeout_s
    while True:
        body = httpx.get(resource_url).json()
        if done(body):
            return body
        if time.time() > deadline:
            raise AssertionError(f"{resource_url} did not get there in {timeout_s} s: {body}")
        time.sleep(poll_s)


def wait_status(url, job_id, statuses, timeout_s=120):
    return wait_for(f"{url}/api/jobs/{job_id}", lambda job: job["status"] in statuses, timeout_s)


def wait_released(url, job_id, timeout_s=60):
    """The job once its runner has let go of it: whatever was in flight is stored, nothing more will be."""
    return wait_for(f"{url}/api/jobs/{job_id}", lambda job: job["runner_id"] is None, timeout_s, poll_s=0.1)


def serve_finished_job(iterations=8):
    """A server on a fresh SQLite file holding one finished job (tuned by the CLI): (process, url)."""
    db = Path(tempfile.mkdtemp()) / "driftlab.db"
    subprocess.run([sys.executable, "-m", "driftlab.cli", "tune", "--iterations", str(iterations),
                    "--seed-points", str(iterations), "--db", str(db), "--name", "finished"],
                   check=True, capture_output=True)
    return start_server(db, free_port())


def age_leases(db_url: str, which) -> None:
    """The leases of the jobs ``which`` selects (a SQLAlchemy condition on Job) as they are LEASE_TIMEOUT_S after
    their runner's last heartbeat: a killed server's, without waiting that long (that a lease holds until then and
    not after: tests/db/test_lease.py)."""
    from sqlalchemy import select

    factory = storage.open_database(db_url)
    try:
        with storage.transaction(factory) as session:
            for job in session.scalars(select(Job).where(which)):
                job.heartbeat_at = naive(utcnow() - timedelta(seconds=LEASE_TIMEOUT_S + 1))
    finally:
        storage.close_database(factory)
