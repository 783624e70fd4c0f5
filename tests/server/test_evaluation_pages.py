"""The evaluations page cache: byte for byte what serializing the rows gives, new evaluations appear, a job id reused
after a delete is another job."""

import json

import numpy as np

from driftlab.db import lifecycle, storage
from driftlab.server.evaluation_pages import EvaluationPages
from driftlab.server.serialize import evaluation_dict


def _add(factory, job_id, n):
    with storage.transaction(factory) as session:
        for i in range(n):
            storage.add_evaluation(session, job_id=job_id, theta={"k": 0.01 * i}, J=float(i), status="completed",
                                   metrics={"mean_abs_e_m": 0.1}, trigger_points=[], wall_ms=1.0, columns=["t"],
                                   trajectory=np.zeros((2, 1)))


def _uncached(factory, job_id, after, limit):
    with storage.snapshot(factory) as session:
        return json.dumps([evaluation_dict(e) for e in storage.evaluations(session, job_id=job_id, after=after,
                                                                             limit=limit)])


def test_pages_are_what_serializing_the_rows_gives_as_the_job_grows(tmp_path):
    factory = storage.open_database(f"sqlite:///{tmp_path / 'pages.db'}")
    with storage.transaction(factory) as session:
        job_id = storage.create_job(session, name="j", spec={"iterations": 50}, seed=0).id
    pages = EvaluationPages()
    for added in (0, 7, 1, 12):
        _add(factory, job_id, added)
        for after, limit in ((-1, 1000), (-1, 3), (4, 5), (18, 1000), (30, 10)):
            with storage.snapshot(factory) as session:
                assert pages.page(session, job_id=job_id, after=after, limit=limit) == _uncached(
                    factory, job_id, after, limit)


def test_a_job_id_reused_after_a_delete_is_another_job(tmp_path):
    factory = storage.open_database(f"sqlite:///{tmp_path / 'reuse.db'}")
    pages = EvaluationPages()
    with storage.transaction(factory) as session:
        job_id = storage.create_job(session, name="first", spec={"iterations": 50}, seed=0).id
    _add(factory, job_id, 5)
    with storage.snapshot(factory) as session:
        assert len(json.loads(pages.page(session, job_id=job_id, after=-1, limit=1000))) == 5
    with storage.transaction(factory) as session:
        lifecycle.delete_job(session, job_id=job_id)
    with storage.transaction(factory) as session:
        again = storage.create_job(session, name="second", spec={"iterations": 50}, seed=0)
        again.created_at = again.created_at.replace(microsecond=(again.created_at.microsecond + 1) % 1_000_000)
    _add(factory, again.id, 2)
    with storage.snapshot(factory) as session:
        page = pages.page(session, job_id=again.id, after=-1, limit=1000)
    assert page == _uncached(factory, again.id, -1, 1000) and len(json.loads(page)) == 2
