"""What a request that breaks the API's rules is answered, in-process (the routes' answers need no runner): every
number typed as JSON states it, ids out of any range, malformed bodies; one error shape, nothing stored."""

import pytest

from tests.server.conftest import in_process_client


@pytest.fixture(scope="module")
def api(tmp_path_factory):
    """One app for the module: every request here is refused, so none changes what the next one sees."""
    with in_process_client(tmp_path_factory.mktemp("validation") / "api.db") as client:
        yield client

HUGE = ["99999999999999999999999", "9223372036854775808", str(2**70)]


@pytest.mark.parametrize("path", [
    "/api/jobs/{n}", "/api/evaluations/{n}", "/api/evaluations/{n}/trajectory", "/api/jobs/1/evaluations?after={n}",
    "/api/evaluations/{n}/recording.viser", "/api/jobs/{n}/best",
])
def test_out_of_range_ids_are_404_or_422_never_500(api, path):
    for n in HUGE + ["0", "-5"]:
        r = api.get(path.format(n=n))
        assert r.status_code in (404, 422), (path, n, r.status_code, r.text)
    r = api.post(f"/api/jobs/{HUGE[1]}/pause")
    assert r.status_code in (404, 422)


@pytest.mark.parametrize(("body", "field"), [
    ({"iterations": True}, "iterations"),
    ({"iterations": "40"}, "iterations"),
    ({"iterations": 40.0}, "iterations"),
    ({"iterations": 5, "seed": False}, "seed"),
    ({"iterations": 5, "seed_points": "3"}, "seed_points"),
    ({"iterations": 5, "config": {"plant.steer_lag_s": "0.03"}}, "plant.steer_lag_s"),
    ({"iterations": 5, "config": {"plant": {"friction_circle": 1}}}, "plant.friction_circle"),
    ({"iterations": 5, "config": {"mpc.horizon": 20.5}}, "mpc.horizon"),
    ({"iterations": 5, "bounds": {"k": ["0", "0.1"]}}, "bounds"),
    ({"iterations": 5, "config": {"mpc.no_such": 1}}, "mpc.no_such"),
])
def test_numbers_are_strict(api, body, field):
    """Inside config and bounds too: a JSON document states its types (the CLI's --set parses text)."""
    before = api.get("/api/jobs").json()
    r = api.post("/api/jobs", json=body)
    assert r.status_code == 422 and field in r.json()["detail"]
    assert any(field in e["field"] for e in r.json().get("errors", [])), r.json()
    assert api.get("/api/jobs").json() == before  # nothing stored


def test_study_config_values_are_strict_too(api):
    bad = [({"kind": "seeds", "seeds": [0], "spec": {"iterations": 2, "config": {"plant.mass_scale": "1.1"}}},
            "plant.mass_scale"),
           ({"kind": "seeds", "seeds": [0], "spec": {"iterations": 2, "bounds": {"k": ["0", 0.1]}}}, "spec.bounds.k"),
           ({"kind": "robustness", "theta": {"k": "0.05"}, "grid": {"plant.mass_scale": [1.0]}}, "theta"),
           ({"kind": "robustness", "theta": {"k": 0.05}, "grid": {"plant.mass_scale": [1.0, "1.1"]}},
            "plant.mass_scale")]
    for body, field in bad:
        r = api.post("/api/studies", json=body)
        assert r.status_code == 422 and field in r.json()["detail"], (body, r.text)


def test_config_errors_have_the_same_shape_as_schema_errors(api):
    r = api.post("/api/jobs", json={"iterations": 5, "bounds": {"k": [0.0, 5.0]}})
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "bounds.k"


def test_invalid_json_is_a_422_naming_the_body(api):
    r = api.post("/api/jobs", content=b'{"iterations": 3,', headers={"content-type": "application/json"})
    assert r.status_code == 422 and r.json()["detail"].startswith("body:")
    not_utf8 = api.post("/api/jobs", content=b'{"iterations": 5, "name": "\xff\xfe"}',
                          headers={"content-type": "application/json"})
    assert not_utf8.status_code == 422 and not_utf8.json()["errors"][0]["field"] == "body"


def test_an_enqueued_theta_names_at_least_one_value(api):
    job = api.post("/api/jobs", json={"iterations": 5}).json()
    r = api.post(f"/api/jobs/{job['id']}/enqueue", json={"thetas": [{"k": 0.05}, {}]})
    assert r.status_code == 422 and r.json()["errors"][0]["field"].startswith("thetas.1"), r.text
    assert api.post(f"/api/jobs/{job['id']}/enqueue", json={"thetas": [{"k": 0.05}]}).status_code == 202
    api.delete(f"/api/jobs/{job['id']}")


def test_a_job_posted_while_the_drift_check_compiles_is_stored_at_once_and_checked_when_it_starts(tmp_path):
    """A fresh install compiles the drift check the first time it runs (~20 s of a core): a job posted meanwhile is
    answered 201 with a warning saying its drift is checked when it starts, and a runner that claims it fails it
    naming the plant's missing drift (the 422 the post would have given)."""
    from driftlab.db import storage
    from driftlab.server.drift_check import DEFERRED
    from driftlab.worker.job_loop import claim_job, run_job
    from tests.server.conftest import InThreadExecutor

    with in_process_client(tmp_path / "deferred.db") as client:
        client.app.state.drift_check.ready.clear()  # as while warm_in_background compiles
        body = {"iterations": 2, "config": {"plant.friction_scale": 1.15}}  # no drift at 44 m (test_drivability)
        posted = client.post("/api/jobs", json=body)
        assert posted.status_code == 201 and DEFERRED in posted.json()["warning"]
        client.app.state.drift_check.ready.set()
        refused = client.post("/api/jobs", json=body)
        assert refused.status_code == 422 and "the plant" in refused.json()["detail"]
    factory = storage.open_database(f"sqlite:///{tmp_path / 'deferred.db'}")
    job_id = posted.json()["id"]
    claim_job(factory, job_id, "runner")
    executor = InThreadExecutor(pool=None)
    assert run_job(factory, job_id, executor, runner="runner", workers=1) == "failed"
    assert executor.submitted == 0
    with storage.snapshot(factory) as session:
        error = storage.get_job(session, job_id=job_id).error
    assert "the plant" in error and "left circle" in error and "44 m" in error
