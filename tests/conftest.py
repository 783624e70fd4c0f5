"""Fixtures every test folder may use."""

import os
import subprocess
import sys

import pytest
from threadpoolctl import threadpool_limits

# One BLAS thread in each test process and in every process it starts, as in the service's worker processes: the
# fast tier runs on both cores at once (pytest-xdist, README), and two processes' BLAS threads each on 2 cores
# made it slower than one process (2 min 40 s either way, against 1 min 39 s with one thread each).
os.environ["OMP_NUM_THREADS"] = "1"
threadpool_limits(limits=1)


@pytest.fixture(scope="session")
def postgres():
    """A real PostgreSQL server for the session (tests/postgres_server.py): ``postgres.new_database()`` gives the
    URL of a new empty database."""
    from tests.postgres_server import PostgresServer

    server = PostgresServer()
    yield server
    server.stop()


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items):
    """Under ``-n N --dist loadgroup`` (the README's test command) the browser tests run one after another on one
    worker: two software-rendered browsers at once on 2 cores starve each other's WebGL. First among the hooks:
    xdist's own reads the group marks (and suffixes the test's id with ``@browser``); run after it, as a conftest's
    hook is, the marks came too late and the browser tests ran on both workers."""
    for item in items:
        if "browser" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.xdist_group("browser"))


# An episode of each plant, short: the first compiles the kernels into numba's cache, the others load them.
_WARM_UP_COMMAND = [sys.executable, "-m", "driftlab.cli", "episode", "--set", "scenario.max_time_s=2", "--plant"]
# The BMW's drift window on the circles a calibration tiles: the drift families most tests' processes read (job
# checks, calibrations), solved into the cache of solved results (driftlab.core) on the core the compile leaves free.
_FAMILIES_COMMAND = [sys.executable, "-m", "driftlab.cli", "equilibrium", "--window", "--plant", "commonroad_std"]
_warming_up: list[subprocess.Popen] = []  # the controller's MB episode while it compiles, under xdist


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session):
    """Under xdist, the controller compiles the episode kernels before any test runs: on a fresh clone (no numba
    cache) each test process and each server a test starts compiled the same kernel at once otherwise (~40 s of a
    core each, several at a time on 2 cores, while browser tests waited on their pages). MB first: its loop compiles
    the shared kernel too. The workers start and collect meanwhile, on the core the compile leaves free, as does the
    BMW's drift window (``_FAMILIES_COMMAND``); no test is handed out before both end
    (:func:`pytest_xdist_node_collection_finished`). With the caches warm this costs ~5 s."""
    if hasattr(session.config, "workerinput") or not session.config.getoption("numprocesses", None):
        return
    for command in (_FAMILIES_COMMAND, [*_WARM_UP_COMMAND, "commonroad_mb"]):
        _warming_up.append(subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE))


def pytest_xdist_node_collection_finished(node, ids):
    """The controller hands out tests once every worker has collected: the kernels are compiled by then."""
    if not _warming_up:
        return
    while _warming_up:
        process = _warming_up.pop()
        _, err = process.communicate(timeout=900)
        assert process.returncode == 0, err.decode(errors="replace")[-2000:]
    rest = [subprocess.Popen([*_WARM_UP_COMMAND, plant], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            for plant in ("commonroad_std", "default")]  # the kernel is compiled: these load it
    assert all(p.wait(timeout=900) == 0 for p in rest)
