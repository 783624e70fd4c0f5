"""A real ``driftlab serve`` process on a free port with its own SQLite file, for end-to-end tests."""

import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx


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


def wait_status(url, job_id, statuses, timeout_s=120):
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        job = httpx.get(f"{url}/api/jobs/{job_id}").json()
        if job["status"] in statuses:
            return job
        time.sleep(0.2)
    raise AssertionError(f"job {job_id} stuck in {job['status']}")


def wait_released(url, job_id, timeout_s=60):
    """The job once its runner has let go of it: whatever was in flight is stored, nothing more will be."""
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        job = httpx.get(f"{url}/api/jobs/{job_id}").json()
        if job["runner_id"] is None:
            return job
        time.sleep(0.1)
    raise AssertionError(f"job {job_id} still held by {job['runner_id']}")


def serve_finished_job(iterations=8):
    """A server on a fresh SQLite file holding one finished job (tuned by the CLI): (process, url)."""
    db = Path(tempfile.mkdtemp()) / "driftlab.db"
    subprocess.run([sys.executable, "-m", "driftlab.cli", "tune", "--iterations", str(iterations),
                    "--seed-points", str(iterations), "--db", str(db), "--name", "finished"],
                   check=True, capture_output=True)
    return start_server(db, free_port())
