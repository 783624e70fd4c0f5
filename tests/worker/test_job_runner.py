"""The server's job runner with several jobs at once, on a real SQLite file and an in-process fake executor
(a pool of threads as its "workers", cheap episodes): a seeds study's jobs run side by side sharing the workers,
a paused job leaves the others running, and no evaluation is numbered twice.

Nothing here asserts on timing: a gate in the fake executor holds the first episodes until the workers are full
with episodes of two jobs at once (or lets them go after a while, and the test then fails on what it saw).
"""

import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np
import pytest

from driftlab.core.robust import MAX_ROBUST_SAMPLES
from driftlab.core.tuning import TuningSpec
from driftlab.db import lifecycle, storage, studies
from driftlab.services.studies import start_study
from driftlab.worker.executors import EpisodeOutcome
from driftlab.worker.job_runner import JobRunner
from driftlab.worker.slots import EpisodeSlots

SPEC = {"iterations": 8, "seed_points": 4, "robust_samples": 2, "confirm_samples": 1}


class FakeCluster:
    """``workers`` threads; an episode's seed tells its job (a job's episode seeds are seed * 64 + j). Counts what
    is in flight (submitted, not yet back) and which jobs it belongs to. Until the gate opens, episodes wait:
    it opens once every worker holds an episode and two jobs are among them (``opened_full``), or after
    ``gate_s`` regardless."""

    def __init__(self, workers: int, episode_s: float = 0.002, gate_s: float = 20.0) -> None:
        self.workers, self.episode_s = workers, episode_s
        self.pool = ThreadPoolExecutor(workers + 8)  # more threads than workers: oversubscription would show
        self.lock = threading.Lock()
        self.in_flight: dict[int, int] = {}  # job seed -> episodes in flight
        self.peak = 0
        self.jobs_at_once = 0
        self.gate = threading.Event()
        self.opened_full = False
        self.gate_deadline = time.monotonic() + gate_s

    def _episode(self, theta, seed):
        while not self.gate.wait(0.01):
            if time.monotonic() > self.gate_deadline:
                self.gate.set()
        time.sleep(self.episode_s)
        with self.lock:
            job = seed // MAX_ROBUST_SAMPLES
            self.in_flight[job] -= 1
        j = (theta["k"] - 0.05) ** 2 * 100 + 0.01 * seed - 2.0
        return EpisodeOutcome.packing(theta=dict(theta), seed=seed, status="completed", J=j,
                                      metrics={"completed_fraction": 1.0, "mean_abs_e_m": 0.1}, trigger_points=[],
                                      wall_ms=1.0, columns=["t_s"], trajectory=np.zeros((2, 1)))

    def submit(self, theta, config_doc, seed=0) -> Future:
        with self.lock:
            job = seed // MAX_ROBUST_SAMPLES
            self.in_flight[job] = self.in_flight.get(job, 0) + 1
            total = sum(self.in_flight.values())
            busy = sum(n > 0 for n in self.in_flight.values())
            self.peak = max(self.peak, total)
            self.jobs_at_once = max(self.jobs_at_once, busy)
            if not self.gate.is_set() and total >= self.workers and busy >= 2:
                self.opened_full = True
                self.gate.set()
        return self.pool.submit(self._episode, theta, seed)

    def shutdown(self) -> None:
        self.gate.set()
        self.pool.shutdown(wait=True)


@pytest.fixture
def factory(tmp_path):
    return storage.open_database(f"sqlite:///{tmp_path / 'runner.db'}")


def _runner(factory, cluster: FakeCluster) -> JobRunner:
    runner = JobRunner(factory, workers=cluster.workers, poll_s=0.02)
    runner.start(executor=cluster)
    return runner


def _wait(condition, timeout_s=60.0, what="the condition"):
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)


def _indices(factory, job_id):
    with storage.snapshot(factory) as session:
        return [e.index for e in storage.evaluations(session, job_id=job_id)]


def _status(factory, job_id):
    with storage.snapshot(factory) as session:
        job = storage.get_job(session, job_id=job_id)
        return job.status, job.runner_id


def test_slots_split_the_capacity_fairly_and_a_job_that_leaves_frees_its_share():
    slots = EpisodeSlots(4)
    for owner in "abc":
        slots.join(owner)
    assert [slots.share(o) for o in "abc"] == [2, 1, 1]
    assert [slots.try_take("a") for _ in range(3)] == [True, True, False]
    assert slots.try_take("b") and slots.try_take("c") and not slots.try_take("c")
    assert slots.in_flight == 4
    slots.leave("c")  # its episode no longer counts, its share goes to a and b
    assert [slots.share(o) for o in "ab"] == [2, 2] and slots.in_flight == 3
    assert slots.try_take("b") and not slots.try_take("b") and slots.peak == 4
    slots.join("d")  # a newcomer's share is taken from the others as their episodes come back
    assert [slots.share(o) for o in "abd"] == [2, 1, 1] and not slots.try_take("d")
    slots.give_back("b")
    slots.give_back("b")
    assert slots.try_take("d") and slots.try_take("b") and not slots.try_take("b") and not slots.try_take("d")


def test_an_episodes_return_wakes_only_a_job_the_full_capacity_held_back():
    slots = EpisodeSlots(4)
    wakes = {owner: threading.Event() for owner in "abc"}
    for owner in "ab":
        slots.join(owner, wakes[owner])
    assert all(slots.try_take(o) for o in "aabb")  # every job at its share, the capacity full
    slots.give_back("a")
    assert not wakes["b"].is_set()  # at its share: the freed slot is not one it may take
    assert slots.try_take("a")
    slots.join("c", wakes["c"])  # shares now 2, 1, 1: b holds one more than its share, c none
    slots.give_back("b")
    assert wakes["c"].is_set() and not wakes["a"].is_set()  # c could start one now; a is at its share
    assert slots.try_take("c")


def test_a_seeds_studys_jobs_run_at_once_sharing_the_workers_and_number_their_evaluations_once(factory):
    with storage.transaction(factory) as session:
        study = start_study(session, doc={"kind": "seeds", "seeds": [1, 2, 3], "spec": SPEC})
        study_id = study.id
        job_ids = [j.id for j in studies.study_jobs(session, study_id=study_id)]
    cluster = FakeCluster(workers=4)
    runner = _runner(factory, cluster)
    seen_running: set[int] = set()
    try:
        def finished():
            seen_running.update(runner.running_job_ids)
            with storage.snapshot(factory) as session:
                return studies.study_status(session, studies.get_study(session, study_id=study_id)) == "finished"

        _wait(finished, what="the study to finish")
    finally:
        runner.stop()
    assert cluster.opened_full, "the workers were never full with episodes of two jobs at once"
    assert cluster.jobs_at_once >= 2 and cluster.peak <= cluster.workers
    assert len(seen_running) >= 2
    with storage.snapshot(factory) as session:
        spans = []
        for job_id in job_ids:
            stored = storage.evaluations(session, job_id=job_id)
            assert [e.index for e in stored] == list(range(SPEC["iterations"]))
            spans.append((min(e.created_at for e in stored), max(e.created_at for e in stored)))
    # Interleaved: some job stored an evaluation before another job's last and after its first.
    assert any(a0 < b1 and b0 < a1 for i, (a0, a1) in enumerate(spans) for (b0, b1) in spans[i + 1:])


def _job(factory, name, seed, iterations):
    spec = TuningSpec.from_dict({**SPEC, "iterations": iterations, "seed": seed})
    with storage.transaction(factory) as session:
        return storage.create_job(session, name=name, spec=spec.to_dict(), seed=seed).id


def test_pausing_one_job_leaves_the_other_running_and_it_resumes_without_repeats(factory):
    a, b = _job(factory, "a", 1, 400), _job(factory, "b", 2, 60)
    cluster = FakeCluster(workers=2)
    runner = _runner(factory, cluster)
    try:
        _wait(lambda: len(_indices(factory, a)) >= 2 and len(_indices(factory, b)) >= 2, what="both jobs to store")
        assert runner.running_job_ids == [a, b]
        with storage.transaction(factory) as session:
            lifecycle.request_pause(session, job_id=a)
        _wait(lambda: _status(factory, a) == ("paused", None), what="a to stop")
        n_a = len(_indices(factory, a))
        assert _status(factory, b) == ("running", runner.runner_id)
        n_b = len(_indices(factory, b))
        _wait(lambda: len(_indices(factory, b)) > n_b, what="b to store after a stopped")
        _wait(lambda: _status(factory, b) == ("finished", None), what="b to finish")
        assert len(_indices(factory, a)) == n_a  # a stopped after its episodes in flight, and stays stopped
        _wait(lambda: runner.running_job_ids == [], what="the runner to let go of b")
        with storage.transaction(factory) as session:
            lifecycle.extend(session, job_id=a, iterations=n_a + 10)
            lifecycle.requeue(session, job_id=a)
        runner.wake()
        _wait(lambda: _status(factory, a) == ("finished", None), what="a to finish after its resume")
    finally:
        runner.stop()
    assert _indices(factory, a) == list(range(n_a + 10)) and _indices(factory, b) == list(range(60))
    assert cluster.peak <= cluster.workers


def test_a_robustness_study_runs_beside_a_job_and_both_finish(factory):
    job = _job(factory, "first", 4, 6)
    with storage.transaction(factory) as session:
        study_id = start_study(session, doc={"kind": "robustness", "theta": {"k": 0.05}, "robust_samples": 2,
                                             "grid": {"plant.mass_scale": [0.9, 1.0, 1.1]}}).id
    cluster = FakeCluster(workers=2, gate_s=0.0)
    runner = _runner(factory, cluster)
    try:
        def study_finished():
            with storage.snapshot(factory) as session:
                return studies.get_study(session, study_id=study_id).status == "finished"

        _wait(study_finished, what="the robustness study")
        _wait(lambda: _status(factory, job) == ("finished", None), what="the job")
    finally:
        runner.stop()
    assert _status(factory, job) == ("finished", None) and _indices(factory, job) == list(range(6))
    with storage.snapshot(factory) as session:
        assert all(c.status == "completed" for c in studies.cells(session, study_id=study_id))


def test_a_wake_looks_for_every_kind_of_work_while_jobs_run(factory):
    """A job's end looks only at the job queue; a request's wake (runner.wake(), as the API calls it) looks for
    every kind of work: a robustness study queued while a job runs starts at the wake, long before the runner's
    poll would look (a minute here)."""
    job = _job(factory, "long", 4, 400)
    cluster = FakeCluster(workers=2, gate_s=0.0)
    runner = JobRunner(factory, workers=cluster.workers, poll_s=60.0, busy_poll_s=60.0)
    runner.start(executor=cluster)
    try:
        _wait(lambda: runner.running_job_ids == [job] and _indices(factory, job), what="the job to run")
        with storage.transaction(factory) as session:
            study_id = start_study(session, doc={"kind": "robustness", "theta": {"k": 0.05}, "robust_samples": 2,
                                                 "grid": {"plant.mass_scale": [0.9, 1.0]}}).id
        runner.wake()
        _wait(lambda: runner.current_study_id == study_id, timeout_s=20, what="the study to start at the wake")
        assert runner.running_job_ids == [job]
    finally:
        runner.stop()


def test_jobs_beyond_the_workers_start_as_jobs_end_and_one_queued_without_a_wake_at_the_poll(factory):
    """A job's end claims the next job while the last claim left some behind (three jobs, two workers: the third
    starts when one ends, long before the runner's poll); once a claim found the queue empty, a job's end claims
    nothing, and a job queued elsewhere (no wake: the CLI, another server) starts at the runner's poll."""
    jobs = [_job(factory, f"queued-{i}", i + 1, 6) for i in range(3)]
    cluster = FakeCluster(workers=2, gate_s=0.0)
    runner = JobRunner(factory, workers=cluster.workers, poll_s=60.0, busy_poll_s=60.0)
    runner.start(executor=cluster)
    try:
        _wait(lambda: all(_status(factory, j)[0] == "finished" for j in jobs), timeout_s=30,
              what="three jobs on two workers to finish without a poll")
        runner.busy_poll_s = runner.poll_s = 0.05
        runner.wake()  # the loop's wait takes the shorter poll from its next look
        long_job = _job(factory, "long", 7, 400)
        _wait(lambda: runner.running_job_ids == [long_job], timeout_s=30, what="the long job to start at a poll")
        later = _job(factory, "queued-later", 8, 4)
        _wait(lambda: _status(factory, later)[0] == "finished", timeout_s=30,
              what="a job queued without a wake to start at a poll while another runs")
    finally:
        runner.stop()
        cluster.shutdown()


def test_the_cli_runs_a_seeds_studys_jobs_at_once_too(factory):
    """`driftlab study seeds` runs the study's jobs as the server's runner does: side by side on the shared
    workers, never more episodes in flight than workers, each job numbered once; a finished job is not rerun."""
    from driftlab.cli.study import _run_seeds_jobs

    with storage.transaction(factory) as session:
        study = start_study(session, doc={"kind": "seeds", "seeds": [1, 2, 3], "spec": SPEC})
        study_id = study.id
        job_ids = [j.id for j in studies.study_jobs(session, study_id=study_id)]
    cluster = FakeCluster(workers=4)
    try:
        _run_seeds_jobs(factory, study_id, cluster, cluster.workers, "cli-test")
    finally:
        cluster.shutdown()
    assert cluster.opened_full, "the workers were never full with episodes of two jobs at once"
    assert cluster.jobs_at_once >= 2 and cluster.peak <= cluster.workers
    with storage.snapshot(factory) as session:
        assert studies.study_status(session, studies.get_study(session, study_id=study_id)) == "finished"
        for job_id in job_ids:
            assert [e.index for e in storage.evaluations(session, job_id=job_id)] == list(range(SPEC["iterations"]))
    again = FakeCluster(workers=4, gate_s=0.0)
    try:
        _run_seeds_jobs(factory, study_id, again, again.workers, "cli-test")
    finally:
        again.shutdown()
    assert again.peak == 0  # every job was finished: nothing ran again


@pytest.mark.parametrize("kind", ["seeds", "robustness"])
def test_a_sigterm_lost_in_a_finalizer_pauses_a_cli_study(factory, kind):
    """SIGTERM whose KeyboardInterrupt Python dropped (it landed in a finalizer: driftlab.cli.shutdown) still stops
    `driftlab study` at its next check, and the study is left paused, not run to its end."""
    from driftlab.cli import shutdown
    from driftlab.cli.study import _run_cells, _run_seeds_jobs

    doc = ({"kind": "seeds", "seeds": [1, 2], "spec": SPEC} if kind == "seeds" else
           {"kind": "robustness", "theta": {"k": 0.05}, "robust_samples": 2,
            "grid": {"plant.mass_scale": [0.9, 1.0, 1.1]}})
    with storage.transaction(factory) as session:
        study_id = start_study(session, doc=doc).id
        job_ids = [j.id for j in studies.study_jobs(session, study_id=study_id)]
    cluster = FakeCluster(workers=2, gate_s=0.0)
    shutdown._terminated.set()
    try:
        with pytest.raises(KeyboardInterrupt):
            if kind == "seeds":
                _run_seeds_jobs(factory, study_id, cluster, cluster.workers, "cli-test")
            else:
                _run_cells(factory, study_id, cluster, cluster.workers, "cli-test")
    finally:
        shutdown._terminated.clear()
        cluster.shutdown()
    with storage.snapshot(factory) as session:
        study = studies.get_study(session, study_id=study_id)
        if kind == "seeds":
            assert {_status(factory, job_id)[0] for job_id in job_ids} <= {"paused", "queued"}
            assert all(len(_indices(factory, job_id)) < SPEC["iterations"] for job_id in job_ids)
        else:
            assert study.status == "paused"
            assert any(c.status == studies.PENDING for c in studies.cells(session, study_id=study_id))


def test_a_study_a_job_a_rescore_and_a_calibration_run_at_once_on_one_runner(factory):
    """Every kind of leased work runs on its own thread within its share of the shared episode slots: while a
    robustness study's grid runs, the runner still claims a job, a rescore and a calibration, and all four have
    episodes in flight together; none of them waits for another to end."""
    from driftlab.core.calibration_request import CalibrationRequest
    from driftlab.db import calibrations, rescores
    from driftlab.db.models import Calibration, Rescore

    # Each far longer than the test waits: it ends as soon as the four ran at once (a loaded machine fits the
    # calibration's model slowly, and it must still meet the others running).
    job = _job(factory, "job", 4, 400)
    with storage.transaction(factory) as session:
        study_id = start_study(session, doc={"kind": "robustness", "theta": {"k": 0.05}, "robust_samples": 4,
                                             "grid": {"plant.mass_scale": [0.8 + 0.01 * i for i in range(40)]}}).id
        done = storage.create_job(session, name="done", spec=TuningSpec.from_dict(SPEC).to_dict(), seed=0)
        done.status = lifecycle.WorkStatus.FINISHED  # only its rescore is work
        best = storage.add_evaluation(session, job_id=done.id, theta={"k": 0.05}, J=-1.0, status="completed",
                                      metrics={"completed_fraction": 1.0}, trigger_points=[], wall_ms=1.0,
                                      columns=["t_s"], trajectory=np.zeros((1, 1)),
                                      seeds=[{"seed": 0, "status": "completed", "J": -1.0}], trajectory_seed=0)
        rescore_id = rescores.queue(session, job_id=done.id, evaluation_id=best.id, theta={"k": 0.05},
                                    config=done.spec["config"], seeds=list(range(1000, 1400))).id
        request = CalibrationRequest(plant="commonroad_std", points="0.5@44", iterations=20, seeds=2,
                                     sets={"plant.model_drive_coupling": False})
        calibration_id = calibrations.queue(session, request=request.as_dict()).id
    cluster = FakeCluster(workers=4, episode_s=0.2, gate_s=0.0)
    runner = _runner(factory, cluster)
    seen: set[str] = set()
    together = 0
    try:
        def all_four_in_flight():
            nonlocal together
            kinds = {owner[0] if isinstance(owner, tuple) else "job" for owner in runner._slots.owners_in_flight()}
            seen.update(kinds)
            together = max(together, len(kinds))
            return together == 4
        _wait(all_four_in_flight, timeout_s=120, what=f"the four kinds in flight at once (seen {seen})")

        def each_stored_a_result():
            with storage.snapshot(factory) as session:
                return (any(c.status == "completed" for c in studies.cells(session, study_id=study_id))
                        and bool(session.get(Rescore, rescore_id).samples) and bool(_indices(factory, job)))
        _wait(each_stored_a_result, timeout_s=120, what="a cell, a sample and an evaluation stored")
        assert runner.current_study_id == study_id and runner.running_job_ids == [job]
        assert cluster.peak <= cluster.workers  # shared, never oversubscribed (a stop drops what is in flight)
    finally:
        runner.stop()
    with storage.snapshot(factory) as session:
        calibration = session.get(Calibration, calibration_id)  # handed back at the stop, what it said kept
        assert calibration.status in ("queued", "finished")
        assert any(m.startswith("calibrating 0.5 rad @ R 44 m") for m in calibration.messages)
