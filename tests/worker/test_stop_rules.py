"""A job's stop rules (driftlab.core.stopping) through the job loop with cheap fake episodes on a real SQLite file,
and at the REST API's edge."""

import pytest

from driftlab.core.errors import ConfigError
from driftlab.core.stopping import StopRules
from driftlab.core.tuning import TuningSpec
from driftlab.db import lifecycle, storage
from driftlab.worker.job_loop import claim_job, run_job
from tests.server.conftest import in_process_client
from tests.worker.test_job_loop import ShuffledExecutor, run_fake_job


def test_no_improvement_counts_the_best_over_the_last_n_evaluations():
    rule = StopRules(no_improvement_evaluations=3, no_improvement_by=0.05)
    assert rule.reason(0.0, [None, None, None, None]) is None  # nothing completed: no best to improve
    assert rule.reason(0.0, [None, -1.0, -1.0, -1.0]) is None  # a best appeared within the last 3
    assert rule.reason(0.0, [-1.0, -1.0, -1.04, -1.04]).startswith("no improvement: the best J fell by 0.04")
    assert rule.reason(0.0, [-1.0, -1.0, -1.1, -1.1]) is None
    assert StopRules(time_budget_s=60.0).reason(60.0, []) == "time budget: ran 60.0 s of 60 s"
    assert not StopRules().any and StopRules().reason(1e9, [-1.0] * 9) is None
    for bad, field in (({"time_budget_s": 0.0}, "stop.time_budget_s"),
                       ({"no_improvement_evaluations": 0}, "stop.no_improvement_evaluations"),
                       ({"no_improvement_by": -1.0}, "stop.no_improvement_by"), ({"after": 3}, "stop.after")):
        with pytest.raises(ConfigError) as exc:
            StopRules.from_dict(bad)
        assert exc.value.field == field


def _finish(factory, stop, iterations):
    spec = TuningSpec(iterations=iterations, seed_points=4, seed=3, robust_samples=1, confirm_samples=0, stop=stop)
    assert TuningSpec.from_dict(spec.to_dict()) == spec
    job_id = run_fake_job(factory, spec, "stopped")
    return _stored(factory, job_id)


def _stored(factory, job_id):
    with storage.snapshot(factory) as session:
        job = storage.get_job(session, job_id=job_id)
        return job, storage.evaluations(session, job_id=job_id)


def test_a_job_finishes_when_its_best_stops_improving_and_an_extension_runs_a_new_window(tmp_path):
    factory = storage.open_database(f"sqlite:///{tmp_path / 'stop.db'}")
    job, evaluations = _finish(factory, StopRules(no_improvement_evaluations=5, no_improvement_by=100.0), 60)
    # J < 0 everywhere here: the best never falls by 100, so the rule fires 5 evaluations after the space-filling
    # design's 4 (its warm-up: the design explores, it does not try to improve), the evaluations asked by then
    # still completing and stored
    assert job.stop_reason.startswith("no improvement") and 4 + 5 <= len(evaluations) <= 4 + 5 + 2
    assert job.run_s > 0.0 and job.status == "finished"
    with storage.transaction(factory) as session:
        lifecycle.extend(session, job_id=job.id, iterations=80)  # queued again
    claim_job(factory, job.id, "runner")
    assert run_job(factory, job.id, ShuffledExecutor(1), runner="runner", workers=2) == "finished"
    again, more = _stored(factory, job.id)
    # the window counts the new run's evaluations: 5 more at least, then the rule fires again
    assert again.stop_reason.startswith("no improvement") and len(evaluations) + 5 <= len(more) <= len(evaluations) + 7
    assert again.run_s > job.run_s


def test_a_job_finishes_when_its_time_is_spent(tmp_path):
    job, evaluations = _finish(storage.open_database(f"sqlite:///{tmp_path / 'time.db'}"),
                               StopRules(time_budget_s=0.5), 5000)
    assert job.stop_reason.startswith("time budget") and 0 < len(evaluations) < 5000 and job.run_s >= 0.5
    factory = storage.open_database(f"sqlite:///{tmp_path / 'time.db'}")
    with storage.transaction(factory) as session:
        lifecycle.extend(session, job_id=job.id, iterations=5000)  # queued again, its time already spent
    claim_job(factory, job.id, "runner")
    assert run_job(factory, job.id, ShuffledExecutor(1), runner="runner", workers=2) == "finished"
    again, more = _stored(factory, job.id)
    assert again.stop_reason.startswith("time budget") and len(more) == len(evaluations)  # it asked nothing


def test_stop_rules_at_the_api_name_their_field(tmp_path):
    with in_process_client(tmp_path / "api.db") as api:
        bad = api.post("/api/jobs", json={"iterations": 3, "stop": {"time_budget_s": 0}})
        assert bad.status_code == 422 and "time_budget_s" in bad.text
        assert api.post("/api/jobs", json={"iterations": 3, "stop": {"after": 3}}).status_code == 422
        job = api.post("/api/jobs", json={"iterations": 3, "stop": {"no_improvement_evaluations": 40}}).json()
        assert job["spec"]["stop"] == {"time_budget_s": None, "no_improvement_evaluations": 40,
                                       "no_improvement_by": 0.0}
        assert job["stop_reason"] is None and job["run_s"] == 0.0
        cold = api.post("/api/jobs", json={"iterations": 3}).json()
        assert "stop" not in cold["spec"]  # a job without rules stores the document it always did
        jobs_before = len(api.get("/api/jobs").json())
        alone = api.post("/api/jobs", json={"iterations": 3, "stop": {"no_improvement_by": 0.01}})
        assert alone.status_code == 422 and "stop.no_improvement_evaluations" in alone.json()["detail"], alone.text
        assert len(api.get("/api/jobs").json()) == jobs_before  # nothing stored
