"""The local process pool when jobs submit from threads that end (the server runs each job on its own thread)."""

import threading

import pytest

from driftlab.worker.executors import LocalProcessExecutor

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI

SHORT = {"scenario": {"max_time_s": 1.0}}


def test_workers_outlive_the_thread_that_first_submitted_to_them():
    executor = LocalProcessExecutor(2)
    try:
        results = []
        for _ in range(2):  # a job's thread: submits, waits, ends
            thread = threading.Thread(target=lambda: results.append(
                [f.result(timeout=120).status for f in [executor.submit({}, SHORT, s) for s in (0, 1)]]))
            thread.start()
            thread.join()
        assert len(results) == 2 and all(len(r) == 2 for r in results)
    finally:
        executor.shutdown()


def _large_result(marker: str, n_bytes: int) -> bytes:
    """Says it is about to return, then returns ``n_bytes``: the worker then spends a while writing its result."""
    with open(marker, "w"):
        pass
    return b"x" * n_bytes


def test_a_worker_ended_while_it_writes_its_result_leaves_no_thread_waiting(tmp_path):
    """A shutdown that ends a worker in the middle of writing a result (`tune` stopped by SIGTERM mid-episode) left
    the pool's manager thread reading the rest of that message for ever, and the process, at its exit, waiting for
    that thread."""
    import os
    import time

    def read():  # bytes this process has read so far (Linux): the pool's manager thread reads the results
        with open("/proc/self/io") as io:
            return next(int(line.split()[1]) for line in io if line.startswith("rchar:"))

    executor = LocalProcessExecutor(1)
    try:
        executor.pool.submit(os.getpid).result(timeout=120)  # the worker is up
        manager = executor.pool._executor_manager_thread
        marker = tmp_path / "returning"
        executor.pool.submit(_large_result, str(marker), 512 * 2**20)
        while not marker.exists():
            time.sleep(0.001)
        before = read()
        deadline = time.monotonic() + 60
        while read() - before < 2**20 and time.monotonic() < deadline:  # until its result is being read
            time.sleep(0.0005)
    finally:
        executor.shutdown()
    manager.join(timeout=30)
    assert not manager.is_alive()
