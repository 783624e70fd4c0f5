"""Two app servers on one PostgreSQL database share its queue: each job runs under one lease at a time, and when one
server is killed -9 the other takes its jobs over once their leases go stale, losing nothing that was stored."""

import signal

import httpx
import pytest

from driftlab.db.models import Job
from tests.server_process import age_leases, free_port, start_server, wait_for

pytestmark = pytest.mark.e2e

ITERATIONS = 10


def _evaluations(url, job_id):
    return httpx.get(f"{url}/api/jobs/{job_id}/evaluations").json()


def test_two_servers_run_a_queue_each_job_exactly_once_through_a_kill_9(postgres):
    database = postgres.new_database()
    first, first_url = start_server(database, free_port(), extra_args=("--workers", "1"))
    second, second_url = start_server(database, free_port(), extra_args=("--workers", "1"))
    try:
        jobs = [httpx.post(f"{first_url}/api/jobs", json={"name": f"queued-{i}", "iterations": ITERATIONS,
                                                           "seed_points": 4, "robust_samples": 1}).json()
                for i in range(4)]
        ids = [job["id"] for job in jobs]
        # Both servers take jobs from the one queue; wait until the first has stored evaluations of its own.
        mine = f":{first.pid}:"

        def first_runs_one(listed):
            return any(j["id"] in ids and mine in (j["runner_id"] or "") and j["n_done"] >= 2 for j in listed)

        listed = wait_for(f"{second_url}/api/jobs", first_runs_one, timeout_s=180, poll_s=0.1)
        held = {j["id"]: j["runner_id"] for j in listed if j["id"] in ids and j["runner_id"]}
        assert any(f":{second.pid}:" in runner for runner in held.values()), held  # the second runs one too
        stored_before = {job_id: {e["id"] for e in _evaluations(second_url, job_id)} for job_id in ids}
        first.send_signal(signal.SIGKILL)
        first.wait()
        age_leases(database, Job.runner_id.contains(mine))  # the second server, running, finds them stale itself
        # The second server finishes the queue, the dead server's jobs once their leases are stale.
        for job_id in ids:
            done = wait_for(f"{second_url}/api/jobs/{job_id}", lambda job: job["status"] == "finished",
                            timeout_s=240, poll_s=0.5)
            evaluations = _evaluations(second_url, job_id)
            assert done["n_done"] == ITERATIONS
            assert [e["index"] for e in evaluations] == list(range(ITERATIONS))  # contiguous, none twice
            assert stored_before[job_id] <= {e["id"] for e in evaluations}  # nothing stored was lost
            assert len({tuple(sorted(e["theta"].items())) for e in evaluations}) == ITERATIONS
    finally:
        for server in (first, second):
            if server.poll() is None:
                server.terminate()
                server.wait(timeout=30)
