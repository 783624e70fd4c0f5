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
