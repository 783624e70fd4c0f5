"""DriftLab's storage on a real PostgreSQL server: the schema, the lease, the values JSON cannot hold."""

import threading

import numpy as np
import pytest

from driftlab.db import lifecycle, schema, storage
from driftlab.db.models import Job
from driftlab.worker.job_loop import claim_job

pytestmark = pytest.mark.e2e  # starts a PostgreSQL server


def test_a_new_database_is_at_the_head_revision_and_opens_again_as_it_is(postgres):
    url = postgres.new_database()
    factory = storage.open_database(url)
    engine = storage.engine_of(factory)
    assert schema.current_revision(engine) == schema.head_revision()
    with storage.transaction(factory) as session:
        storage.create_job(session, name="kept", spec={"iterations": 3}, seed=0)
    again = storage.open_database(url)
    with storage.snapshot(again) as session:
        assert [job.name for job in storage.list_jobs(session)] == ["kept"]


def test_of_runners_that_claim_one_job_at_once_exactly_one_holds_it(postgres):
    factory = storage.open_database(postgres.new_database())
    with storage.transaction(factory) as session:
        job_id = storage.create_job(session, name="race", spec={"iterations": 3}, seed=0).id
    won, lost, go = [], [], threading.Event()

    def claim(runner: str) -> None:
        go.wait(5)
        try:
            claim_job(factory, job_id, runner)
            won.append(runner)
        except lifecycle.TransitionError:
            lost.append(runner)

    runners = [threading.Thread(target=claim, args=(f"runner-{i}",)) for i in range(8)]
    for runner in runners:
        runner.start()
    go.set()
    for runner in runners:
        runner.join()
    assert len(won) == 1 and len(lost) == 7
    with storage.snapshot(factory) as session:
        assert session.get(Job, job_id).runner_id == won[0]


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_a_metric_that_is_not_a_number_is_stored_as_null(backend, postgres, tmp_path):
    """PostgreSQL refuses NaN in JSON, and the API could not send it: an episode that never took a step has such
    metrics (the lowest wheel load of none)."""
    url = f"sqlite:///{tmp_path / 'd.db'}" if backend == "sqlite" else postgres.new_database()
    factory = storage.open_database(url)
    with storage.transaction(factory) as session:
        job_id = storage.create_job(session, name="nan", spec={"iterations": 3}, seed=0).id
        storage.add_evaluation(session, job_id=job_id, theta={"k": 0.1}, J=5.0, status="diverged",
                               metrics={"mean_abs_e_m": float("nan"), "min_wheel_load_n": [float("inf"), 1.5]},
                               trigger_points=[], wall_ms=1.0, columns=["t"], trajectory=np.zeros((0, 1)))
    with storage.snapshot(factory) as session:
        [stored] = storage.evaluations(session, job_id=job_id)
        assert stored.metrics == {"mean_abs_e_m": None, "min_wheel_load_n": [None, 1.5]}
