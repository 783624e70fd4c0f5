"""Fixtures every test folder may use."""

import os

import pytest
from threadpoolctl import threadpool_limits

# The suite runs its files side by side (pytest-xdist, README): one BLAS thread in each test process and in every
# process it starts, as in the service's worker processes, so that parallel tests do not oversubscribe the cores.
os.environ["OMP_NUM_THREADS"] = "1"
threadpool_limits(limits=1)


def pytest_collection_modifyitems(items):
    """With ``--dist loadgroup`` (README) a file's tests stay together, so its module-scoped server or browser
    starts once; the browser files share one worker, as two software-rendered browsers at once starve each other
    and the servers beside them of the two cores."""
    for item in items:
        path = item.nodeid.split("::")[0]
        item.add_marker(pytest.mark.xdist_group("browser" if path.endswith("_browser.py") else path))


@pytest.fixture(scope="session")
def postgres():
    """A real PostgreSQL server for the session (tests/postgres_server.py): ``postgres.new_database()`` gives the
    URL of a new empty database."""
    from tests.postgres_server import PostgresServer

    server = PostgresServer()
    yield server
    server.stop()
