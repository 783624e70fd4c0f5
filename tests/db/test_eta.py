"""A running job's ETA counts its running time only: a pause before the current run does not slow it down."""

from datetime import timedelta

import numpy as np

from driftlab.db import lifecycle, storage
from driftlab.db.models import Evaluation, Job, utcnow
from driftlab.server.serialize import COMPILING, job_detail, job_dict


def _evaluation(session, job_id, at):
    e = storage.add_evaluation(session, job_id=job_id, theta={"k": 0.1}, J=1.0, status="completed", metrics={},
                               trigger_points=[], wall_ms=1.0, columns=["t"], trajectory=np.zeros((2, 1)))
    session.get(Evaluation, e.id).created_at = at.replace(tzinfo=None)


def test_eta_after_a_three_minute_pause_is_the_rate_since_the_resume(tmp_path):
    factory = storage.open_database(f"sqlite:///{tmp_path / 'eta.db'}")
    t0 = utcnow() - timedelta(minutes=10)
    with storage.transaction(factory) as session:
        job = storage.create_job(session, name="j", spec={"iterations": 60}, seed=0)
        for i in range(40):  # the first run: one evaluation a second
            _evaluation(session, job.id, t0 + timedelta(seconds=i + 1))
    resumed = t0 + timedelta(seconds=40 + 180)  # paused 3 minutes, then claimed again
    with storage.transaction(factory) as session:
        lifecycle.claim(session, job_id=1, runner="r")
        session.get(Job, 1).started_at = resumed.replace(tzinfo=None)
        for i in range(4):
            _evaluation(session, 1, resumed + timedelta(seconds=1.0 * (i + 1)))
    with storage.snapshot(factory) as session:
        shown = job_dict(session, session.get(Job, 1))
    assert shown["n_done"] == 44
    assert abs(shown["eta_s"] - 16.0) <= 0.3 * 16.0  # 16 evaluations left at 1 s each
    # The old rate (the last 20 stamps, the pause among them) said (44 - 25 + 180) / 19 s each: 168 s.
    assert shown["detail"] is None


def test_a_run_with_no_evaluation_yet_has_no_eta_and_says_when_it_compiles(tmp_path, monkeypatch):
    factory = storage.open_database(f"sqlite:///{tmp_path / 'eta.db'}")
    with storage.transaction(factory) as session:
        storage.create_job(session, name="j", spec={"iterations": 60}, seed=0)
        lifecycle.claim(session, job_id=1, runner="r")
    with storage.snapshot(factory) as session:
        assert storage.seconds_per_evaluation(session, job_id=1, since=session.get(Job, 1).started_at) is None
    monkeypatch.setattr("driftlab.services.read_model.episode_kernels_cached", lambda: False)
    assert job_detail("running", None) == COMPILING
    assert job_detail("running", 0.5) is None and job_detail("queued", None) is None
