"""Fixtures every test folder may use."""

import os

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


def pytest_collection_modifyitems(items):
    """Under ``-n N --dist loadgroup`` (the README's test command) the browser tests run one after another on one
    worker: two software-rendered browsers at once on 2 cores starve each other's WebGL."""
    for item in items:
        if "browser" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.xdist_group("browser"))
