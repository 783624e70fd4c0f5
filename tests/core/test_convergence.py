"""One rule for a job's best: the lowest completed J, the earliest on a tie; failures never count."""

import numpy as np

from driftlab.core.convergence import best_position, best_so_far
from driftlab.db import storage


def test_best_position_and_best_so_far_agree_and_skip_failures():
    values = [5.0, -1.0, -3.0, -1.0, -3.0, -9.0]
    completed = [False, True, True, True, True, False]  # the -9 failed: a penalty, not a result
    assert best_position(values, completed) == 2  # -3 twice: the earliest
    assert best_so_far(values, completed) == [None, -1.0, -3.0, -3.0, -3.0, -3.0]
    assert best_position([1.0, 2.0], [False, False]) is None


def test_storage_picks_the_same_best(tmp_path):
    factory = storage.open_database(f"sqlite:///{tmp_path / 'best.db'}")
    values = [5.0, -1.0, -3.0, -1.0, -3.0, -9.0]
    completed = [False, True, True, True, True, False]
    with storage.transaction(factory) as session:
        job_id = storage.create_job(session, name="b", spec={"iterations": 9}, seed=0).id
        for value, ok in zip(values, completed, strict=True):
            storage.add_evaluation(session, job_id=job_id, theta={}, J=value,
                                   status="completed" if ok else "spun_out", metrics={}, trigger_points=[],
                                   wall_ms=1.0, columns=["t"], trajectory=np.zeros((1, 1)))
    with storage.snapshot(factory) as session:
        assert storage.best_evaluation(session, job_id=job_id).index == best_position(values, completed)
