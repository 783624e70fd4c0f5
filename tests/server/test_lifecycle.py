"""One runner per job, no orphans, no 500s: the job lifecycle against real server and CLI processes and a real
SQLite file."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from driftlab.db.models import Job
from tests.server_process import age_leases, free_port, start_server, wait_for, wait_released, wait_status

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI


def _cli(*args, env=None):
    return subprocess.run([sys.executable, "-m", "driftlab.cli", *args], capture_output=True, text=True,
                          timeout=300, env={**os.environ, "OMP_NUM_THREADS": "1", **(env or {})})


def _children(pid: int) -> set[int]:
    """Every descendant process of ``pid`` (from /proc)."""
    parents = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as handle:
                    stat = handle.read()
            except OSError:
                continue
            parents[int(entry)] = int(stat.rsplit(")", 1)[1].split()[1])
    found, frontier = set(), {pid}
    while frontier:
        frontier = {child for child, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as handle:
            return handle.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """One server for the tests below: each leaves its jobs finished or paused and released."""
    db = tmp_path_factory.mktemp("lifecycle") / "driftlab.db"
    proc, url = start_server(db, free_port())
    yield proc, url, db
    if proc.poll() is None:
        proc.terminate()
        proc.wait(timeout=30)


def _wait_done(url, job_id, n, timeout_s=120):
    """Until the job has stored n evaluations (AssertionError after timeout_s)."""
    return wait_for(f"{url}/api/jobs/{job_id}", lambda job: job["n_done"] >= n, timeout_s, poll_s=0.1)


def test_a_second_runner_on_a_running_job_is_refused(server):
    _, url, db = server
    job = httpx.post(f"{url}/api/jobs", json={"name": "race", "iterations": 400, "seed_points": 5}).json()
    _wait_done(url, job["id"], 2)
    other = _cli("tune", "--name", "race", "--db", str(db))
    assert other.returncode == 2
    assert other.stderr.startswith("driftlab: error: job 'race' is being run by server@")
    assert len(other.stderr.strip().splitlines()) == 1
    assert httpx.get(f"{url}/api/jobs/{job['id']}").json()["status"] == "running"
    httpx.post(f"{url}/api/jobs/{job['id']}/pause")
    paused = wait_status(url, job["id"], {"paused"})
    wait_released(url, job["id"])
    evals = httpx.get(f"{url}/api/jobs/{job['id']}/evaluations").json()
    assert [e["index"] for e in evals] == list(range(len(evals))) and len(evals) >= paused["n_done"]


def test_a_second_server_on_a_taken_port_leaves_the_first_ones_jobs_alone(server):
    _, url, db = server
    job = httpx.post(f"{url}/api/jobs", json={"iterations": 200, "seed_points": 5, "robust_samples": 1}).json()
    _wait_done(url, job["id"], 2)
    before = httpx.get(f"{url}/api/jobs/{job['id']}").json()
    port = url.rsplit(":", 1)[1]
    second = subprocess.run([sys.executable, "-m", "driftlab.cli", "serve", "--port", port, "--db", str(db)],
                            capture_output=True, text=True, timeout=60)
    assert second.returncode == 2 and f"--port {port}" in second.stderr
    assert "Traceback" not in second.stderr and "DriftLab:" not in second.stdout
    after = httpx.get(f"{url}/api/jobs/{job['id']}").json()
    assert after["status"] == "running" and after["runner_id"] == before["runner_id"]
    httpx.post(f"{url}/api/jobs/{job['id']}/pause")
    wait_status(url, job["id"], {"paused"})
    wait_released(url, job["id"])


@pytest.mark.parametrize("optimizer_process", ["0", "1"])
def test_kill_9_leaves_no_orphan_workers_and_the_next_server_takes_the_job_over(tmp_path, optimizer_process):
    db = tmp_path / "crash.db"
    proc, url = start_server(db, free_port(), env_extra={"DRIFTLAB_OPTIMIZER_PROCESS": optimizer_process})
    job = httpx.post(f"{url}/api/jobs", json={"iterations": 12, "seed_points": 5, "robust_samples": 1}).json()
    _wait_done(url, job["id"], 4)
    workers = _children(proc.pid)
    assert len(workers) >= 3  # the job's pool, the what-if worker, multiprocessing's helpers
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    deadline = time.time() + 10
    while any(_alive(p) for p in workers) and time.time() < deadline:
        time.sleep(0.2)
    assert not [p for p in workers if _alive(p)], "worker processes outlived a killed server"
    age_leases(f"sqlite:///{db}", Job.id == job["id"])
    proc, url = start_server(db, free_port())
    try:  # the new server takes the job over
        done = wait_status(url, job["id"], {"finished"}, timeout_s=180)
        evals = httpx.get(f"{url}/api/jobs/{job['id']}/evaluations").json()
        assert done["n_done"] == 12 and [e["index"] for e in evals] == list(range(12))
        assert len({tuple(sorted(e["theta"].items())) for e in evals}) == 12
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    assert not [p for p in _children(os.getpid()) if _alive(p) and p in workers]


def test_a_budget_changed_on_a_running_job_is_honoured(server):
    _, url, _ = server
    raised = httpx.post(f"{url}/api/jobs", json={"iterations": 8, "seed_points": 8, "robust_samples": 1}).json()
    _wait_done(url, raised["id"], 6)
    assert httpx.patch(f"{url}/api/jobs/{raised['id']}", json={"iterations": 14}).status_code == 200
    assert wait_status(url, raised["id"], {"finished"})["n_done"] == 14  # raised near the end: not lost
    lowered = httpx.post(f"{url}/api/jobs", json={"iterations": 60, "seed_points": 60, "robust_samples": 1}).json()
    _wait_done(url, lowered["id"], 5)
    for _ in range(50):  # failing evaluations end in milliseconds: the count can pass ours before the PATCH lands
        now = httpx.get(f"{url}/api/jobs/{lowered['id']}").json()["n_done"]
        r = httpx.patch(f"{url}/api/jobs/{lowered['id']}", json={"iterations": now + 1})
        if r.status_code == 200:
            break
        assert r.status_code == 422 and r.json()["detail"].startswith("iterations: "), r.text  # never below stored
    assert r.status_code == 200, r.text
    done = wait_status(url, lowered["id"], {"finished"})
    assert now + 1 <= done["n_done"] <= now + 3  # at most what was in flight (2 workers) beyond the new budget


def test_a_pause_stops_after_the_evaluations_in_flight(server):
    _, url, _ = server
    job = httpx.post(f"{url}/api/jobs", json={"iterations": 300, "seed_points": 100, "robust_samples": 1}).json()
    _wait_done(url, job["id"], 3)
    at_pause = httpx.post(f"{url}/api/jobs/{job['id']}/pause").json()["n_done"]
    after = wait_released(url, job["id"])
    assert after["status"] == "paused"
    # 2 workers: two running and the next theta asked ahead at most (job_loop._may_ask), each completed
    assert at_pause <= after["n_done"] <= at_pause + 3


def test_delete_extend_and_paging(server):
    _, url, _ = server
    job = httpx.post(f"{url}/api/jobs", json={"iterations": 4, "seed_points": 4, "robust_samples": 1}).json()
    wait_status(url, job["id"], {"finished"})
    page = httpx.get(f"{url}/api/jobs/{job['id']}/evaluations", params={"after": 0, "limit": 2}).json()
    assert [e["index"] for e in page] == [1, 2]
    assert httpx.patch(f"{url}/api/jobs/{job['id']}", json={"iterations": 2}).status_code == 422  # below n_done
    extended = httpx.patch(f"{url}/api/jobs/{job['id']}", json={"iterations": 7})
    assert extended.status_code == 200 and extended.json()["iterations"] == 7
    done = wait_status(url, job["id"], {"finished"})
    evals = httpx.get(f"{url}/api/jobs/{job['id']}/evaluations").json()
    assert done["n_done"] == 7 and [e["index"] for e in evals] == list(range(7))
    running = httpx.post(f"{url}/api/jobs", json={"iterations": 300, "seed_points": 5}).json()
    _wait_done(url, running["id"], 1)
    assert httpx.delete(f"{url}/api/jobs/{running['id']}").status_code == 409
    httpx.post(f"{url}/api/jobs/{running['id']}/pause")
    wait_status(url, running["id"], {"paused"})
    wait_released(url, running["id"])  # 409 until the runner has stored what was in flight and let go
    assert httpx.delete(f"{url}/api/jobs/{running['id']}").status_code == 204
    assert httpx.get(f"{url}/api/jobs/{running['id']}").status_code == 404
    assert httpx.get(f"{url}/api/evaluations/{evals[0]['id']}").status_code == 200  # other jobs untouched
    assert httpx.delete(f"{url}/api/jobs/{running['id']}").status_code == 404


def test_tune_extends_a_finished_job_and_tools_share_the_default_database(tmp_path):
    env = {"XDG_DATA_HOME": str(tmp_path / "data"), "DRIFTLAB_DATABASE_URL": ""}
    first = _cli("tune", "--iterations", "3", "--seed-points", "3", "--robust-samples", "1", "--name", "t1", env=env)
    assert first.returncode == 0, first.stderr
    assert (tmp_path / "data" / "driftlab" / "driftlab.db").exists()
    more = _cli("tune", "--iterations", "5", "--name", "t1", env=env)
    assert more.returncode == 0, more.stderr
    assert json.loads(more.stdout)["n_done"] == 5 and json.loads(more.stdout)["status"] == "finished"
    rescored = _cli("rescore", "--name", "t1", "--samples", "2", env=env)  # no --db: the same default file
    assert rescored.returncode == 0, rescored.stderr


@pytest.mark.parametrize(("args", "needle"), [
    (("episode", "--theta", "c_lr=abc"), "theta.c_lr"),
    (("episode", "--theta", "k=0.05,k=0.1"), "'k' twice"),
    (("episode", "--plot", "/nonexistent/dir/ep.png"), "--plot"),
    (("episode", "--plot", "/tmp/ep.txt"), "--plot"),
    (("episode", "--plot", "/tmp"), "--plot"),
    (("episode", "--csv", "/tmp"), "--csv"),
    (("serve", "--port", "99999"), "--port"),
    (("tune", "--workers", "0"), "--workers"),
    (("tune", "--iterations", "2", "--db", "/nonexistent/dir/x.db"), "database /nonexistent/dir/x.db"),
    (("report", "--name", "x", "--out", "/tmp/r", "--baselines", "0"), "--baselines"),
    (("report", "--name", "x", "--out", "/etc/hostname"), "--out"),
])
def test_cli_errors_are_one_line_with_exit_2(args, needle):
    out = _cli(*args)
    assert out.returncode == 2 and needle in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr


# The repository's schemathesis.toml: which operations may answer 422 to a request the schema allows, and why.
SCHEMATHESIS_CONFIG = Path(__file__).resolve().parents[2] / "schemathesis.toml"
ST_TOKEN = "schemathesis-token"


def test_schemathesis_all_checks_pass(tmp_path):
    """Property-based requests from the OpenAPI schema (real HTTP, real server), every check: no 5xx, every status,
    content type and body as documented, invalid input refused, 405 with Allow, the token enforced where the
    schema says so. Small quotas keep the jobs it creates to a few episodes each."""
    quotas = {"DRIFTLAB_MAX_EPISODES_PER_JOB": "16", "DRIFTLAB_MAX_EPISODES_PER_STUDY": "16",
              "DRIFTLAB_MAX_QUEUED_JOBS": "20", "DRIFTLAB_TOKEN": ST_TOKEN}
    proc, url = start_server(tmp_path / "st.db", free_port(), env_extra=quotas, extra_args=("--workers", "1"))
    try:
        out = subprocess.run(["st", "--config-file", str(SCHEMATHESIS_CONFIG), "run", f"{url}/openapi.json",
                              "--checks", "all", "--max-examples", "10", "--seed", "1", "--workers", "1", "--no-color",
                              "--request-timeout", "30", "--generation-database", "none",
                              "-H", f"Authorization: Bearer {ST_TOKEN}"],
                             capture_output=True, text=True, timeout=600, cwd=tmp_path,
                             env={**os.environ,
                                  "PATH": os.path.dirname(sys.executable) + os.pathsep + os.environ["PATH"]})
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    server_log = Path(proc.log_path).read_text(errors="replace")
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:] + "\nserver log:\n" + server_log[-6000:]


def _cache_without_the_episode_loop(folder: Path) -> Path:
    """A copy of this session's numba cache without the episode loop's two kernels. After an install the loop's
    kernels are not in the cache, and those two are what a job's status reads (driftlab.core.compiled); the
    kernels they call load from the copy. Compiling the two costs ~20 s of a core, against ~85 s for every kernel
    from an empty cache (2026-11-28)."""
    here = os.environ.get("NUMBA_CACHE_DIR")
    if here and Path(here).is_dir():
        shutil.copytree(here, folder)
    for kernel in ("run_until_constrained", "finish_step"):
        for cached in folder.rglob(f"closed_loop.{kernel}-*"):
            cached.unlink()
    return folder


def test_a_job_says_compiling_until_its_first_evaluation_after_an_install(tmp_path):
    # One worker process: two would each compile the loop, a core each, for the same answer.
    cache = _cache_without_the_episode_loop(tmp_path / "nb")
    proc, url = start_server(tmp_path / "fresh.db", free_port(), env_extra={"NUMBA_CACHE_DIR": str(cache)},
                             extra_args=("--workers", "1"))
    try:
        # (A post while the server's drift check still compiles: tests/server/test_request_validation.py.)
        posted = httpx.post(f"{url}/api/jobs", json={"iterations": 2, "seed_points": 2}, timeout=10)
        assert posted.status_code == 201, posted.text
        job = posted.json()
        seen = []
        deadline = time.time() + 300
        while time.time() < deadline:
            body = httpx.get(f"{url}/api/jobs/{job['id']}").json()
            seen.append((body["status"], body["n_done"], body["detail"]))
            if body["n_done"] > 0:
                break
            time.sleep(0.5)
        compiling = [s for s in seen if s[2] is not None]
        assert compiling and all(n == 0 and status == "running" for status, n, _ in compiling), seen
        assert "compiling" in compiling[0][2]
        assert seen[-1][1] > 0 and seen[-1][2] is None  # the loop is cached once the first evaluation is in
    finally:
        proc.terminate()
        proc.wait(timeout=30)
