"""A warm start (driftlab.core.warm_start) through the job loop with cheap fake episodes on a real SQLite file: the
same config's evaluations told before the job's own, another config's best thetas asked first, the start stored
with the job; and the REST API's edge."""

import pytest

from driftlab.core.config import EpisodeConfig
from driftlab.core.configure import apply_overrides
from driftlab.core.errors import ConfigError
from driftlab.core.tuning import TuningSpec
from driftlab.core.warm_start import WARM_POINTS
from driftlab.db import storage
from driftlab.services.warm_start import with_warm_start
from driftlab.worker.optimizer_host import restore_optimizer
from tests.server.conftest import in_process_client
from tests.worker.test_job_loop import run_fake_job


def _run(factory, spec, name):
    job_id = run_fake_job(factory, spec, name)
    with storage.snapshot(factory) as session:
        return job_id, storage.evaluations(session, job_id=job_id)


@pytest.fixture
def source(tmp_path):
    factory = storage.open_database(f"sqlite:///{tmp_path / 'warm.db'}")
    job_id, evaluations = _run(factory, TuningSpec(iterations=14, seed_points=4, seed=3, robust_samples=1,
                                                   confirm_samples=0), "source")
    return factory, job_id, evaluations


def test_another_configs_best_thetas_are_asked_first(source):
    factory, source_id, evaluations = source
    other = apply_overrides(EpisodeConfig(), {"scenario.sideslip_rad": 0.38})
    cold = TuningSpec(iterations=6, seed_points=4, seed=5, robust_samples=1, confirm_samples=0, config=other,
                      deterministic=True)
    with storage.snapshot(factory) as session:
        spec = with_warm_start(session, cold, [source_id])
    ranked = sorted((e for e in evaluations if e.completed), key=lambda e: e.J)[:WARM_POINTS]
    assert spec.warm_start.from_jobs == {source_id: "initial"} and not spec.warm_start.told
    assert list(spec.warm_start.initial_points) == [{k: e.theta[k] for k in spec.bounds} for e in ranked]
    assert TuningSpec.from_dict(spec.to_dict()) == spec and "warm_start" not in cold.to_dict()
    _, warm = _run(factory, spec, "warm")
    # asked first, in order, before the untuned theta and the design: the source's best theta leads
    assert [e.theta for e in warm[:2]] == list(spec.warm_start.initial_points[:2])


def test_the_same_configs_evaluations_are_told_before_the_jobs_own(source):
    factory, source_id, evaluations = source
    cold = TuningSpec(iterations=4, seed_points=4, seed=5, robust_samples=1, confirm_samples=0)
    with storage.snapshot(factory) as session:
        spec = with_warm_start(session, cold, [source_id, source_id])  # a repeated id counts once
    assert spec.warm_start.from_jobs == {source_id: "told"} and len(spec.warm_start.told) == len(evaluations)
    optimizer = restore_optimizer(spec, [])
    assert len(optimizer.x) == len(evaluations)  # the design is skipped: the GP proposes from the start
    assert optimizer.best[1] == min(e.J for e in evaluations if e.completed)
    warm_id, warm = _run(factory, spec, "continued")
    assert warm[0].theta not in [e.theta for e in evaluations]
    # The continuation shows where it started: the source's best, told, beside its own best.
    from driftlab.server.serialize import job_dict

    with storage.snapshot(factory) as session:
        shown = job_dict(session, storage.get_job(session, job_id=warm_id))
    source_best = min((e for e in evaluations if e.completed), key=lambda e: e.J)
    assert shown["best_told"] == {"theta": source_best.theta, "J": source_best.J, "from_jobs": [source_id]}


def test_an_unknown_source_is_refused_naming_the_field(source, tmp_path):
    factory, source_id, _ = source
    with storage.snapshot(factory) as session, pytest.raises(ConfigError, match="warm_start_from: no job with id 99"):
        with_warm_start(session, TuningSpec(iterations=4), [source_id, 99])
    with in_process_client(tmp_path / "api.db") as api:
        body = {"iterations": 3, "config": {"plant.model": "driftlab"}}
        first = api.post("/api/jobs", json=body).json()
        bad = api.post("/api/jobs", json={**body, "warm_start_from": [first["id"], 12345]})
        assert bad.status_code == 422 and "warm_start_from" in bad.text
        assert api.post("/api/jobs", json={**body, "warm_start_from": []}).status_code == 422
        warm = api.post("/api/jobs", json={**body, "warm_start_from": [first["id"]]})
        assert warm.status_code == 201, warm.text
        assert warm.json()["spec"]["warm_start"]["from_jobs"] == [{"job_id": first["id"], "used_as": "told"}]
