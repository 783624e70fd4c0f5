"""A request the resource's status does not allow is a 409 with the reason, for jobs and studies alike, and changes
nothing (one handler: driftlab.db.lifecycle.TransitionError)."""

from tests.server.conftest import in_process_client


def test_transitions_a_status_does_not_allow_are_409_with_the_reason_and_change_nothing(tmp_path):
    with in_process_client(tmp_path / "conflicts.db") as api:
        job = api.post("/api/jobs", json={"iterations": 3}).json()
        refused = api.post(f"/api/jobs/{job['id']}/resume")
        assert refused.status_code == 409
        assert refused.json() == {"detail": f"job {job['id']} is queued; resume needs paused or failed"}
        assert api.post(f"/api/jobs/{job['id']}/pause").json()["status"] == "paused"
        again = api.post(f"/api/jobs/{job['id']}/pause")
        assert again.status_code == 409 and "pause needs queued or running" in again.json()["detail"]
        assert api.get(f"/api/jobs/{job['id']}").json()["status"] == "paused"

        study = api.post("/api/studies", json={"kind": "seeds", "seeds": [1, 2], "spec": {"iterations": 2}})
        assert study.status_code == 201, study.text
        sid = study.json()["id"]
        assert api.post(f"/api/studies/{sid}/pause").status_code == 200
        paused_again = api.post(f"/api/studies/{sid}/pause")
        assert paused_again.status_code == 409 and "no queued or running job" in paused_again.json()["detail"]
        job_ids = api.get(f"/api/studies/{sid}").json()["job_ids"]
        assert len(job_ids) == 2
        for job_id in job_ids:  # a seeds study's job goes only with its study
            alone = api.delete(f"/api/jobs/{job_id}")
            assert alone.status_code == 409 and f"DELETE /api/studies/{sid}" in alone.json()["detail"]
        assert api.get(f"/api/studies/{sid}").status_code == 200
