"""Hand-picked thetas (POST /api/jobs/{id}/enqueue): evaluated next, before the optimizer's proposals, stored marked
and taken off the queue in the same commit; at the API's edge, refused with the field named."""

from driftlab.core.config import Theta
from driftlab.core.tuning import TuningSpec
from driftlab.db import enqueued, storage
from driftlab.worker.job_loop import claim_job, run_job
from tests.server.conftest import in_process_client
from tests.worker.test_job_loop import ShuffledExecutor


def test_enqueued_thetas_are_evaluated_next_and_marked(tmp_path):
    factory = storage.open_database(f"sqlite:///{tmp_path / 'enqueue.db'}")
    spec = TuningSpec(iterations=8, seed_points=4, seed=3, robust_samples=1, confirm_samples=0)
    with storage.transaction(factory) as session:
        job_id = storage.create_job(session, name="picked", spec=spec.to_dict(), seed=spec.seed).id
        enqueued.enqueue(session, job_id=job_id, thetas=[spec.picked_theta({"k": 0.07}),
                                                          spec.picked_theta({"dV": -0.2, "k": 0.01})])
    claim_job(factory, job_id, "runner")
    assert run_job(factory, job_id, ShuffledExecutor(0), runner="runner", workers=1) == "finished"
    with storage.snapshot(factory) as session:
        evaluations = storage.evaluations(session, job_id=job_id)
        assert not enqueued.waiting(session, job_id=job_id)  # taken off the queue as they were stored
    untuned = {k: Theta().as_dict()[k] for k in spec.bounds}
    assert [e.theta for e in evaluations[:2]] == [{**untuned, "k": 0.07}, {**untuned, "dV": -0.2, "k": 0.01}]
    assert [e.enqueued for e in evaluations] == [True, True] + [False] * 6


def test_the_api_enqueues_inside_the_jobs_box_and_names_what_it_refuses(tmp_path):
    with in_process_client(tmp_path / "api.db") as api:
        job = api.post("/api/jobs", json={"iterations": 3}).json()
        url = f"/api/jobs/{job['id']}/enqueue"
        r = api.post(url, json={"thetas": [{"k": 0.06}, {"c_lr": 0.01, "dV": 0.2}]})
        assert r.status_code == 202, r.text
        body = r.json()
        assert len(body["enqueued"]) == 2 and [w["theta"]["k"] for w in body["waiting"]] == [0.06, 0.05]
        assert api.get(url).json()["waiting"] == body["waiting"]
        for bad, field in (({"k": 0.5}, "thetas.0.k"), ({"spin": 1.0}, "thetas.0.spin")):
            refused = api.post(url, json={"thetas": [bad]})
            assert refused.status_code == 422 and field in refused.text, refused.text
        assert api.post(url, json={"thetas": []}).status_code == 422
        assert api.post(url, json={"thetas": [{"k": "0.05"}]}).status_code == 422  # numbers are strict
        assert api.post("/api/jobs/999/enqueue", json={"thetas": [{"k": 0.05}]}).status_code == 404
        assert len(api.get(url).json()["waiting"]) == 2  # nothing refused was stored


def test_the_queue_holds_no_more_than_the_job_will_evaluate(tmp_path):
    """Sixty requests of 100 thetas each once left 6,002 waiting on a 50-evaluation job: a theta past the budget
    would wait for ever. What is left of the budget bounds the queue; a refusal stores nothing."""
    with in_process_client(tmp_path / "bounded.db") as api:
        job = api.post("/api/jobs", json={"iterations": 5}).json()
        url = f"/api/jobs/{job['id']}/enqueue"
        assert api.post(url, json={"thetas": [{"k": 0.01 * n} for n in range(4)]}).status_code == 202
        over = api.post(url, json={"thetas": [{"k": 0.06}, {"k": 0.07}]})
        assert over.status_code == 409 and "5 evaluations left and 4 thetas waiting: at most 1 more" in over.text
        assert len(api.get(url).json()["waiting"]) == 4
        assert api.post(url, json={"thetas": [{"k": 0.06}]}).status_code == 202  # the last one fits
        assert api.patch(f"/api/jobs/{job['id']}", json={"iterations": 7}).status_code == 200
        assert api.post(url, json={"thetas": [{"k": 0.07}, {"k": 0.08}]}).status_code == 202  # a larger budget


def test_sixty_requests_of_a_hundred_fill_the_cap_and_the_rest_is_refused_naming_it(tmp_path):
    """A 5000-evaluation job: at most MAX_WAITING thetas wait at once (a 409 names the cap and stores nothing), each
    answer lists a page of them with the count in all, and GET pages through the rest by id."""
    from driftlab.services.enqueue import MAX_WAITING, WAITING_PAGE

    with in_process_client(tmp_path / "capped.db") as api:
        job = api.post("/api/jobs", json={"iterations": 5000}).json()
        url = f"/api/jobs/{job['id']}/enqueue"
        answers = [api.post(url, json={"thetas": [{"k": 0.001 * (n % 100)} for n in range(100)]})
                   for _ in range(60)]
        accepted = [a for a in answers if a.status_code == 202]
        assert len(accepted) == MAX_WAITING // 100
        assert all(a.status_code == 409 and f"at most {MAX_WAITING} waiting" in a.text for a in answers[10:])
        last = accepted[-1].json()
        assert last["n_waiting"] == MAX_WAITING and len(last["waiting"]) == WAITING_PAGE  # a page, not the queue
        first = api.get(url).json()
        second = api.get(url, params={"after": first["waiting"][-1]["id"]}).json()
        assert second["waiting"][0]["id"] > first["waiting"][-1]["id"] and second["n_waiting"] == MAX_WAITING
